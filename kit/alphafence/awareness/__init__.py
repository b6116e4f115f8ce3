"""What the monitor knows of its surroundings, without I/O: the fences in one metric frame
(an STRtree, a grid, rays along the track, time windows, vertical references), other
aircraft, stopping distance and time to breach, alert states, positions provably clear of
every fence. The monitor's engine, the post-flight review and the live map read it."""
