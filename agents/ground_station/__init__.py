"""Guidance service, referee, UAV tasking and recorder. So far: the
capture-the-flag arena of a map (``ctf_arena``) and the on-disk cache of
solved games (``ctf_cache``) the guidance service will answer from."""
