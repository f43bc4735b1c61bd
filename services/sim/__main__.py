"""python -m services.sim"""

import sys

from services.runtime import run_service
from services.sim import SERVICE

sys.exit(run_service(SERVICE))
