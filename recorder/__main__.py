import sys

from recorder.process import main

sys.exit(main())
