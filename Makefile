# Developer conveniences.  The README's two commands are scripts/demo.sh and
# scripts/test.sh; these targets are for working on insnav.
PY ?= python3
LOCK = flock /tmp/insnav-build.lock

.PHONY: dev test cpp-test sanitize bench
dev:            ## editable install (Python edits live; re-run after C++ edits)
	$(LOCK) $(PY) -m pip install --no-build-isolation -q -e .[test] -Ceditable.mode=redirect
test:
	scripts/test.sh
cpp-test:       ## plain C++ example + tests (no Python)
	$(LOCK) sh -c 'cmake -S . -B build/cpp -DINSNAV_BUILD_EXAMPLES=ON -DCMAKE_BUILD_TYPE=Release >/dev/null && cmake --build build/cpp -j2 && ctest --test-dir build/cpp --output-on-failure'
sanitize:       ## the same under ASan + UBSan
	$(LOCK) sh -c 'cmake -S . -B build/asan -DINSNAV_BUILD_EXAMPLES=ON -DINSNAV_SANITIZE=ON -DCMAKE_BUILD_TYPE=RelWithDebInfo >/dev/null && cmake --build build/asan -j2 && ctest --test-dir build/asan --output-on-failure'
bench:
	$(PY) bench/run_all.py
