"""Fixed-point weights and the tally slots shared by the Monte Carlo kernels."""

W_ONE = 2**36  # fixed-point weight of a launched packet (about 1.5e-11 resolution)

# tally slots (per thread slot, int64 fixed-point weights)
T_LAUNCHED = 0
T_SPECULAR = 1
T_TOP = 2
T_BOTTOM = 3
T_SIDES = 4
T_OUTSIDE_ABSORBED = 5
T_KILLED = 6
T_MISSED = 7
T_ROULETTE = 8  # weight created by roulette survivors minus weight of packets killed
T_ABSORBED_EXCLUDED = 9  # absorbed inside by packets that failed the deposition criteria
N_TALLY = 10
