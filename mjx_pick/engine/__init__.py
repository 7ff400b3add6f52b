"""The one simulation path: a backend per engine (MuJoCo C, MJX-JAX, MuJoCo Warp) behind one
protocol, the runner (batches, chunks, resume, progress, cancel; local or on Ray) and the
study-facing simulator.
"""
