"""Run the tracker service: ``python -m services.tracker``."""

import sys

from services.runtime import run_service
from services.tracker import SERVICE

sys.exit(run_service(SERVICE))
