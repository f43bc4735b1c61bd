"""python -m services.realsense"""

import sys

from services.realsense import SERVICE
from services.runtime import run_service

sys.exit(run_service(SERVICE))
