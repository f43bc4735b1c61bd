"""python -m services.controller"""

import sys

from services.controller import SERVICE
from services.runtime import run_service

sys.exit(run_service(SERVICE))
