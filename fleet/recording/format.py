"""What a recording of a run is, as an MCAP file (docs/recording.md): the names the writer
and the reader agree on.

Each zenoh key is a channel whose messages are the raw msgpack payloads as they travelled
(message encoding `msgpack`, a JSON schema per message type: fleet.recording.schemas); log
time is when the message was received, publish time its simulation time. The run's
description is a metadata record and the layout a TOML attachment, so a recording stands on
its own. View channels under /view/ carry Foxglove scene messages (protobuf) for Foxglove
to display, and those under /vda5050/ an external session's VDA 5050 messages as JSON with
the official schemas (copies of what the vda5050.mqtt channels hold).
"""

PROFILE = "forklift-fleet"
MCAP_MAGIC = b"\x89MCAP0\r\n"  # every MCAP file starts with it
MESSAGE_ENCODING = "msgpack"
VIEW_PREFIX = "/view/"
VDA5050_PREFIX = "/vda5050/"
VIEW_PREFIXES = (VIEW_PREFIX, VDA5050_PREFIX)  # channels for Foxglove, not the run's messages
SEGMENT_METADATA = "segment"  # {"run_id": the run directory's}: which run a file is of
RUN_METADATA = "run"  # the run's description (fleet.recording.writer.run_metadata)
LAYOUT_ATTACHMENT = "layout.toml"
NS = 1_000_000_000  # MCAP times are nanoseconds
