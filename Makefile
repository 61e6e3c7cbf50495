# The README's commands.  Each target creates the local virtual environment (.venv) and
# installs gonio into it on first use, so a fresh clone needs only Python 3.10+ and make.
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
OUT    ?= gonio-demo
# pytest-xdist workers: "auto" uses every core.
JOBS   ?= auto

.PHONY: demo test bench figures clean help

help:
	@echo "make demo    run gonio's main job end to end on the embedded emulator (output in $(OUT)/)"
	@echo "make test    run the test suite"
	@echo "make bench   run the speed and accuracy benchmarks (JSON + charts in docs/benchmarks/)"
	@echo "make clean   remove the virtual environment and generated output"

# gonio is installed editable; its bytecode is compiled here, since an editable install
# leaves that to the first run, which cannot write it where PYTHONDONTWRITEBYTECODE is
# set, and every start would compile gonio's modules again (0.15-0.20 s of CPU in
# `gonio fit`, docs/fitting.md "Performance").
$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test]'
	$(BIN)/python -m pip install --quiet --no-deps instrumentkit==0.6.0
	$(BIN)/python -m compileall -q gonio drivers
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/gonio demo --out $(OUT)

test: $(STAMP)
	$(BIN)/python -m pytest -n $(JOBS) tests --doctest-modules gonio drivers

bench: $(STAMP)
	$(BIN)/python benchmarks/run_all.py

clean:
	rm -rf $(VENV) $(OUT) .pytest_cache .hypothesis
