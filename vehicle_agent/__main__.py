from fleet.runtime.lifecycle import leave
from vehicle_agent.process import main

leave(main())
