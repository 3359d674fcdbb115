"""What a recording of a run is, as an MCAP file (docs/recording.md): the names the writer
and the reader agree on.

Each zenoh key is a channel whose messages are the raw msgpack payloads as they travelled
(message encoding `msgpack`, a JSON schema per message type: fleet.recording.schemas); log
time is when the message was received, publish time its simulation time. The run's
description is a metadata record and the layout a TOML attachment, so a recording stands on
its own. View channels under /view/ carry Foxglove scene messages (protobuf) for Foxglove
to display.
"""

PROFILE = "forklift-fleet"
MCAP_MAGIC = b"\x89MCAP0\r\n"  # every MCAP file starts with it
MESSAGE_ENCODING = "msgpack"
VIEW_PREFIX = "/view/"
SEGMENT_METADATA = "segment"  # {"run_id": the run directory's}: which run a file is of
RUN_METADATA = "run"  # the run's description (fleet.recording.writer.run_metadata)
LAYOUT_ATTACHMENT = "layout.toml"
NS = 1_000_000_000  # MCAP times are nanoseconds
