"""E2VID (Rebecq et al., TPAMI 2019) and FireNet (Scheerlinck et al., WACV 2020): events -> intensity video.

voxel.py       event windows -> normalised 5-bin voxel grids (pure functions)
networks.py    the recurrent UNet and FireNet, parameter names as in the official code
official.py    loading official checkpoints (E2VID_lightweight.pth.tar and friends)
synth.py       on-the-fly training sequences from the project's own simulator
train.py       `e4dgs train-e2vid`: resumable training
reconstruct.py running a network over an event file; the high-pass-filter baseline
"""

import common  # noqa: F401  (first: it sets the OpenMP wait policy before torch or numba loads)
