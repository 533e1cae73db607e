# Two entry points (README.md): `make demo` and `make test`; each creates .venv if needed.
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

$(STAMP): pyproject.toml
	test -d $(VENV) || $(PY) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e ".[test]"
	touch $(STAMP)

.PHONY: venv demo test test-slow bench clean
venv: $(STAMP)

demo: $(STAMP)
	mkdir -p out stm_files
	$(BIN)/fracas run namelists/earth_mars_guidance.toml
	$(BIN)/fracas propagate namelists/leo_j2.toml -o out/leo_j2.h5 --plot out/leo_j2.png
	$(BIN)/fracas propagate namelists/earth_mars_sep.toml -o out/earth_mars_sep.h5 --plot out/earth_mars_sep.png
	$(BIN)/fracas propagate namelists/near_earth_spiral.toml -o out/near_earth_spiral.h5 --plot out/near_earth_spiral.png
	$(BIN)/fracas run namelists/earth_mars_team.toml -o out/earth_mars_team.h5 --plot out/earth_mars_team.png
	$(BIN)/fracas stm build namelists/mercury_approach_team.toml -o stm_files/mercury_approach.h5
	$(BIN)/fracas stm info stm_files/mercury_approach.h5
	$(BIN)/fracas run namelists/mercury_approach_team.toml --stm stm_files/mercury_approach.h5
	$(BIN)/fracas run namelists/mercury_approach_guidance.toml --quiet
	$(BIN)/fracas report out/earth_mars_team.h5 --quiet
	$(BIN)/fracas sweep namelists/earth_mars_sweep.toml --workers 0
	$(BIN)/fracas run namelists/near_earth_spiral_tom.toml -o out/near_earth_spiral_tom.h5
	$(BIN)/fracas run namelists/near_earth_spiral_team.toml --trajectory-deck out/near_earth_spiral_tom_reference.toml --quiet
	$(BIN)/fracas run namelists/earth_mars_tsim.toml
	$(BIN)/fracas run namelists/apollo12_rendezvous.toml
	$(BIN)/fracas run namelists/earth_mars_rendezvous_tom.toml
	$(BIN)/fracas import-namelist namelists/legacy/earth_mars_team.nml -o out/imported_earth_mars_team.toml --force
	$(BIN)/fracas validate out/imported_earth_mars_team.toml
	$(BIN)/fracas export out/earth_mars_team.h5 --oem out/earth_mars_team.oem

# the whole suite but the slow reference subset (< 10 min cold on CI's 2 cores); CI runs both.
# Two pytest-xdist workers (one per core: XLA compiles on one thread); --dist loadfile keeps a
# module's tests, and so its module-scoped fixtures and compiled programs, on one worker.
TEST_WORKERS ?= 2
PYTEST := $(BIN)/python -m pytest -q -n $(TEST_WORKERS) --dist loadfile --durations=20

test: $(STAMP)
	$(PYTEST) -m "not slow"

test-slow: $(STAMP)
	$(PYTEST) -m slow

bench: $(STAMP)
	$(BIN)/pip install --quiet -e ".[bench]"
	$(BIN)/python benchmarks/bench_core.py --quick

clean:
	rm -rf out .pytest_cache
