from fleet.runtime.lifecycle import leave
from reservation.service import main

leave(main())
