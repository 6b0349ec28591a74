"""Training and test data: procedural animated scenes path-traced with Mitsuba 3 into deep EXRs.

scene.py (scene descriptions and presets), trace.py (the Dr.Jit path tracer returning every sample),
binning.py (samples -> deep-Z / deep-OID bins, references into the noisy bins), render.py (one frame's deep
images and motion vectors), dataset.py (a dataset on disk). Mitsuba is imported lazily (mitsuba_env.py).
"""
