# Two commands from a fresh clone (only Python 3.11 needed):
#   make book   build the HTML book in _build/html (executes every notebook, book mode)
#   make test   unit tests + every notebook through nbmake, in fast mode (FACELIB_FAST=1)
#   make chapter N=05 [FAST=1]   execute one chapter and print its time (outputs in _build/chapters/)
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed-stamp
export VTK_DEFAULT_OPENGL_WINDOW := vtkEGLRenderWindow
export PIP_DISABLE_PIP_VERSION_CHECK := 1
WORKERS ?= 2

.PHONY: venv data book test chapter clean

$(STAMP): requirements.txt requirements-test.txt pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet -r requirements.txt -r requirements-test.txt
	$(BIN)/python -m pip install --quiet --no-deps --no-build-isolation -e .
	touch $(STAMP)

venv: $(STAMP)

data: venv
	$(BIN)/python -m facelib data

book: venv
	$(BIN)/python -m facelib data
	$(BIN)/jupyter-book build . --builder html --all -W --keep-going
	@echo "The book is in _build/html/index.html"

# One chapter, as in class: make chapter N=05 (book mode), make chapter N=05 FAST=1 (fast mode).
chapter: venv
	@$(BIN)/python -m facelib chapter "$(N)" $(if $(FAST),--fast)

# One torch thread per test worker: two workers with two OpenMP threads each on two cores thrash.
test: venv
	FACELIB_FAST=1 $(BIN)/python -m facelib data
	FACELIB_FAST=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1 $(BIN)/python -m pytest -n $(WORKERS) --nbmake --nbmake-timeout=1200 --durations=8 tests book

clean:
	rm -rf _build .pytest_cache
