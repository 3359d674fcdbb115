"""The VDA 5050 gateway process (`fleet vda5050 gateway`, `python -m vda5050`): every forklift
of a run as a VDA 5050 AGV on MQTT. The protocol's pure parts (schemas, map, orders, one
forklift's execution, the messages) are in fleet/vda5050/."""
