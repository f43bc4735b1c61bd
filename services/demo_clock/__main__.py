"""python -m services.demo_clock"""

import sys

from services.demo_clock import SERVICE
from services.runtime import run_service

sys.exit(run_service(SERVICE))
