"""The phone emulator and the walkers that carry it."""
