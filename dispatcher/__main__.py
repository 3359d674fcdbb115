from dispatcher.process import main
from fleet.runtime.lifecycle import leave

leave(main())
