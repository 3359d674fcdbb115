from fleet.runtime.lifecycle import leave
from recorder.process import main

leave(main())
