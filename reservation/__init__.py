"""The reservation service process (`fleet reservation`, `python -m reservation`): the run's
authoritative space-time reservation table (store.py) and its journal (journal.py), served on
zenoh (service.py); every process that reads the table keeps a mirror of it (mirror.py)."""
