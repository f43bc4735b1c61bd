"""Run the detector service: ``python -m services.detector``."""

import sys

from services.detector import SERVICE
from services.runtime import run_service

sys.exit(run_service(SERVICE))
