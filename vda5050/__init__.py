"""The VDA 5050 gateway package: every emulated vehicle as a VDA 5050 AGV on MQTT (issue 22).

`vda5050.schemas` holds the official JSON schemas of VDA 5050 2.0.0 and validates messages
against them, `vda5050.map` the map a master builds orders on, `vda5050.orders` one
vehicle's orders."""

# The topics in the order of the specification's chapter 6 (here, not in `schemas`, so the
# command line names them without loading jsonschema).
TOPICS = ("order", "instantActions", "state", "visualization", "connection", "factsheet")
