"""Stage 7, run: the benchmark grid of methods x tasks x seeds (`runner`) and the clock its
speed figures come from (`timing`)."""
