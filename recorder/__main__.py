import sys

from fleet.cli import main

sys.exit(main(["recorder", *sys.argv[1:]]))
