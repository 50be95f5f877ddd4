"""The capture-the-flag game's time to win by fast sweeping (``game``), a
second method beside marching the time-dependent HJI equation."""
