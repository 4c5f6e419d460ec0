# Two entry points (see README.md):  `make lab`  and  `make test`.
# Both create .venv with Python 3.11, install torch (CPU wheel) first, then environment.txt,
# then this repository in editable mode so `solutions` and `graders` import everywhere.
PYTHON ?= python3.11
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

.PHONY: install lab test bench fetch-data clean-notebooks

install: $(STAMP)

$(STAMP): environment.txt pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --upgrade pip
	$(BIN)/python -m pip install torch==2.13.0
	$(BIN)/python -m pip install -r environment.txt
	$(BIN)/python -m pip install --no-deps -e .
	$(BIN)/python -c "import torch; assert torch.version.cuda is None, 'a CUDA torch was installed'"
	touch $(STAMP)

lab: install
	$(BIN)/jupyter lab notebooks/

test: install
	$(BIN)/python -m pytest

bench: install
	$(BIN)/python -m benchmarks

fetch-data: install
	$(BIN)/python -m graders.datasets fetch --all

clean-notebooks: install
	$(BIN)/python -m graders.notebook_tools strip notebooks/*.ipynb
