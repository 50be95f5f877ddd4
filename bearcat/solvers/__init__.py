"""Pure numerics: arrays in, result dataclasses out; no files, sockets or clocks."""
