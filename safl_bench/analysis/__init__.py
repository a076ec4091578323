"""Reports on results and data, after the run: why a cell scored what it did (`explain`) and
how close the synthetic default is to real KITTI (`fidelity`)."""
