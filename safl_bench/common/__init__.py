"""What every stage needs: atomic writes (`atomic`), content fingerprints (`fingerprint`), the
fan-out of independent jobs to processes or a Ray cluster (`parallel`), and the loop-pair
definition that both the synthetic generator and the ground truth use (`loops`).

Nothing here imports another stage; every stage may import it.
"""
