import sys

from grip_force_ros.lab.cli import main

sys.exit(main())
