# One-command set-up. `make demo` installs and runs the main job; `make test` installs and runs the tests.
PY ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: install demo test docs test-slow bench bench-learn model line-model clean

$(STAMP): pyproject.toml
	$(PY) -m venv $(VENV)
	$(BIN)/pip install -q --upgrade pip
	# the local CPU wheel first, so the project's torch range installs nothing more
	$(BIN)/pip install -q torch==2.13.0
	$(BIN)/pip install -q -e ".[formats,test,dask,parquet,jpk,docs]"
	touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	$(BIN)/stickslip demo --out stickslip-demo

test: $(STAMP)
	$(BIN)/ruff check src tests benchmarks scripts
	$(BIN)/python -m pytest -q -m "not slow"
	$(MAKE) docs

# the docs site, strictly (any warning fails), executing the tutorials; then site/
docs: $(STAMP)
	$(BIN)/python scripts/docs_api.py
	NO_MKDOCS_2_WARNING=1 PATH="$(abspath $(BIN)):$$PATH" NUMBA_NUM_THREADS=$${NUMBA_NUM_THREADS:-2} $(BIN)/mkdocs build --strict --site-dir build/site

test-slow: $(STAMP)
	$(BIN)/python -m pytest -q -m slow

bench: $(STAMP)
	$(BIN)/python benchmarks/simulate.py
	$(BIN)/python benchmarks/classical.py

bench-learn: $(STAMP)
	$(BIN)/python benchmarks/paper_table.py
	$(BIN)/python benchmarks/lattice_mapping.py
	$(BIN)/python benchmarks/noise_robustness.py
	$(BIN)/python benchmarks/inference_speed.py --threads 1
	$(BIN)/python benchmarks/lab_bench.py
	$(BIN)/python benchmarks/coverage_check.py
	$(BIN)/python benchmarks/encoder_vs_mlp.py
	$(BIN)/python benchmarks/soft_contacts.py
	$(BIN)/python benchmarks/soft_contacts.py --model classical
	$(BIN)/python benchmarks/noise_bias.py

model: $(STAMP)
	$(BIN)/python scripts/train_default_model.py

# train the bundled line model, calibrate it on the effect families, refit its domain reference
line-model: $(STAMP)
	$(BIN)/python scripts/train_line_model.py --out build/line-train/line_model_trained.pt
	$(BIN)/python benchmarks/families.py --line-model build/line-train/line_model_trained.pt \
	    --write src/stickslip/resources/line_model.pt
	$(BIN)/python benchmarks/domain.py --write-reference

clean:
	rm -rf $(VENV) stickslip-demo build
