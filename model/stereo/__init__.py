"""The stereo branch, RAFT-Stereo style: one file per idea (features, correlation, GRU update,
convex upsampling) and :mod:`model.stereo.raft` wiring them."""
