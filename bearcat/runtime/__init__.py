"""The two runners of the same agents: ``simulate`` (in-process, virtual
time) and ``launch``/``live`` (one process per peer over Zenoh), each with
its fault injector, and what a live run needs around them: credentials,
run directories, a full disk, solving the sets before or behind a game."""
