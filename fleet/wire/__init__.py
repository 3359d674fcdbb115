"""What travels between processes: the message catalogue (docs/protocol.md) and the conversions
between core objects and messages."""
