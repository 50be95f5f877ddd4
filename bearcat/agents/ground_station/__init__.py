"""The ground station: the guidance service and its advisors, the referee,
UAV tasking, the on-disk cache of solved capture-the-flag games
(``ctf_cache``) and the run's recording."""
