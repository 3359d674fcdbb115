"""VDA 5050 2.0.0, pure: `schemas` holds the official JSON schemas and validates messages
against them, `map` the map a master builds orders on, `orders` one vehicle's orders,
`execution` what one emulated forklift does with them, `messages` what it sends. The gateway
process that puts them on MQTT is the `vda5050` package beside fleet/ (docs/vda5050.md)."""

# The topics in the order of the specification's chapter 6 (here, not in `schemas`, so the
# command line names them without loading jsonschema).
TOPICS = ("order", "instantActions", "state", "visualization", "connection", "factsheet")
