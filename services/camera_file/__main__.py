"""python -m services.camera_file"""

import sys

from services.camera_file import SERVICE
from services.runtime import run_service

sys.exit(run_service(SERVICE))
