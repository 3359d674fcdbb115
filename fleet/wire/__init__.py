"""What travels between processes: the message catalogue (docs/protocol.md), the catalogue of
topics it travels on, and the conversions between core objects and messages."""
