import sys

from services.planner import SERVICE
from services.runtime import run_service

sys.exit(run_service(SERVICE))
