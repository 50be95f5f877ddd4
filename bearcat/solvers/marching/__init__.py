"""Fast marching: the eikonal equation with a speed map and the modified method of thesis 4.1.3,
paths down its travel times, and the open-loop reach-avoid game of chapter 4 built on them."""
