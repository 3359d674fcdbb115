"""Recordings as MCAP files (docs/recording.md): the format and its schemas, the writer, the
reader, a run's segments, run directories, the in-process run written as a recording, and the
mission record rebuilt from one."""
