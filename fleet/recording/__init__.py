"""Recordings as MCAP files (docs/recording.md): the format, run directories, the in-process run
written as a recording, and the mission record rebuilt from one."""
