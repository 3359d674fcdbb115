import sys

from dispatcher.process import main

sys.exit(main())
