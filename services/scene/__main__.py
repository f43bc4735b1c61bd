"""python -m services.scene"""

import sys

from services.runtime import run_service
from services.scene import SERVICE

sys.exit(run_service(SERVICE))
