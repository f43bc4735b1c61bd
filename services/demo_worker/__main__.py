"""python -m services.demo_worker"""

import sys

from services.demo_worker import SERVICE
from services.runtime import run_service

sys.exit(run_service(SERVICE))
