"""The VDA 5050 gateway package: every emulated vehicle as a VDA 5050 AGV on MQTT (issue 22).

`vda5050.schemas` holds the official JSON schemas of VDA 5050 2.0.0 and validates messages
against them."""
