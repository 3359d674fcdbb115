"""`python -m vda5050`: the VDA 5050 gateway process (`fleet vda5050 gateway`)."""

from fleet.runtime.lifecycle import leave
from vda5050.gateway import main

leave(main())
