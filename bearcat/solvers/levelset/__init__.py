"""The level-set solver: time-dependent reach-avoid HJI equations (thesis 3.2) on N-D grids, their kernels
(CPU and CUDA), the Hamiltonians they take, and the devices they run on."""
