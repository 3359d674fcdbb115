import sys

from reservation.service import main

sys.exit(main())
