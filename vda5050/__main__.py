"""`python -m vda5050`: the VDA 5050 gateway process (`fleet vda5050 gateway`)."""

import sys

from vda5050.gateway import main

sys.exit(main())
