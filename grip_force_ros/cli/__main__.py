import sys

from grip_force_ros.cli import main

sys.exit(main())
