"""What every stage needs: atomic writes (`atomic`), content fingerprints (`fingerprint`), the
fan-out of independent jobs to processes or a Ray cluster (`parallel`), the loop-pair definition
that both the synthetic generator and the ground truth use (`loops`), and how a stage package
stands for the old module of its name (`oldmodule`).

Nothing here imports another stage; every stage may import it.
"""
