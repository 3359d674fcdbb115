import sys

from vehicle_agent.process import main

sys.exit(main())
