# Two entry points (see README.md):  `make lab`  and  `make test`.
# Both create .venv with Python 3.11, install torch (CPU wheel) first, then environment.txt,
# then this repository in editable mode so `solutions` and `graders` import everywhere.
PYTHON ?= $(shell command -v python3.11 || command -v python3)
# PyPI's Linux torch wheel is a multi-GB CUDA build: take the CPU build from PyTorch's index when it
# is reachable (machines that only reach PyPI mirrors carry the CPU wheel locally: see pip config).
TORCH_CPU_INDEX := https://download.pytorch.org/whl/cpu
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

.PHONY: install lab test bench fetch-data clean-notebooks

install: $(STAMP)

$(STAMP): environment.txt pyproject.toml
	@$(PYTHON) -c "import sys; assert sys.version_info[:2] == (3, 11), 'Python 3.11 is required, found ' + sys.version.split()[0]"
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -c "import urllib.request as u; u.urlopen('$(TORCH_CPU_INDEX)/', timeout=5)" 2>/dev/null \
	  && $(BIN)/python -m pip install torch==2.13.0 --index-url $(TORCH_CPU_INDEX) \
	  || $(BIN)/python -m pip install torch==2.13.0
	$(BIN)/python -m pip install -r environment.txt
	$(BIN)/python -m pip install --no-deps -e .
	$(BIN)/python -c "import torch; assert torch.version.cuda is None, 'a CUDA torch was installed'"
	touch $(STAMP)

lab: install
	$(BIN)/python -m graders.study.lab $(LAB_ARGS)

# Both cores (pytest-xdist); each notebook runs whole on one worker (conftest.py); the 25 slowest tests listed at the end.
TEST_WORKERS ?= 3
test: install
	$(BIN)/python -m pytest -n $(TEST_WORKERS) --durations=25

bench: install
	$(BIN)/python -m benchmarks

fetch-data: install
	$(BIN)/python -m graders.datasets fetch --all

clean-notebooks: install
	$(BIN)/python -m tools.notebook_tools strip notebooks/*.ipynb
