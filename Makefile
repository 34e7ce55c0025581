# hpcwedge: `make demo` (the main job) and `make test` (the test suite).
# Both install what is missing first (scripts/setup.sh; quick when done).
PY := .venv/bin/python

.PHONY: setup setup-bench setup-docs demo test docs bench bench-quick check clean

setup:
	@bash scripts/setup.sh

setup-bench:
	@bash scripts/setup.sh bench

setup-docs: setup
	@bash scripts/setup.sh docs

demo: setup
	$(PY) scripts/demo.py

# the docs tools too: tests/test_docs.py builds the site and runs its examples
test: setup setup-docs
	$(PY) -m pytest -q

# the site into site/ (warnings are errors); the scene reference and benchmark pages are
# generated at build time (scripts/mkdocs_hooks.py, scripts/docs_pages.py)
docs: setup-docs
	NO_MKDOCS_2_WARNING=1 $(PY) -m mkdocs build --strict

bench: setup-bench
	$(PY) scripts/bench_2d.py --budget 300
	$(PY) scripts/bench_mu_c.py
	PYTHONPATH=. $(PY) scripts/bench_socp_count.py --brute-max 14
	$(PY) scripts/bench_parallel.py --repeat 3
	PYTHONPATH=. $(PY) scripts/bench_convergence.py --refine 1 2 4 8 16 32 64
	PYTHONPATH=. $(PY) scripts/bench_convergence.py --patch 0.05 --refine 1 2 4 8 16 32 64 128 256
	PYTHONPATH=. $(PY) scripts/bench_convergence.py --patch 0.05 --patch-kind hat --refine 1 2 4 8 16 32 64 128 256
	PYTHONPATH=. $(PY) scripts/bench_condense.py
	PYTHONPATH=. $(PY) scripts/bench_growth.py
	$(PY) scripts/stress.py
	PYTHONPATH=. $(PY) scripts/stress_3d.py
	PYTHONPATH=. $(PY) scripts/bench_peers.py
	PYTHONPATH=. $(PY) scripts/bench_global_mu_c.py
	PYTHONPATH=. $(PY) scripts/bench_global_mu_c.py --rows 40 80 --engines ours scip_bisect --out results/bench_global_mu_c_large
	PYTHONPATH=. $(PY) scripts/bench_global_mu_c.py --model block2d --rows 19 39 --engines ours scip_bisect --out results/bench_global_mu_c_block2d
	PYTHONPATH=. $(PY) scripts/bench_search_3d.py --full
	PYTHONPATH=. $(PY) scripts/bench_lp_screens.py
	PYTHONPATH=. $(PY) scripts/bench_flags.py
	PYTHONPATH=. $(PY) scripts/bench_socp_solvers.py

bench-quick: setup-bench
	$(PY) scripts/bench_2d.py --quick --out results/quick
	$(PY) scripts/bench_mu_c.py --quick --out results/quick
	$(PY) scripts/stress.py --quick --out results/quick
	PYTHONPATH=. $(PY) scripts/stress_3d.py --quick --out results/quick/stress_3d
	PYTHONPATH=. $(PY) scripts/bench_growth.py --quick --out results/quick/bench_growth
	PYTHONPATH=. $(PY) scripts/bench_peers.py --quick --out results/quick/bench_peers
	PYTHONPATH=. $(PY) scripts/bench_global_mu_c.py --quick --out results/quick/bench_global_mu_c
	PYTHONPATH=. $(PY) scripts/bench_search_3d.py --quick --out results/quick/bench_search_3d

check: setup
	../shared/acceptance/check_public

clean:
	rm -rf .venv build *.egg-info
