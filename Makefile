# Two entry points that work on a fresh machine (Python 3.11 with venv; no GPU needed):
#   make demo   set up .venv and augment the bundled sample scenes (outputs in out/demo)
#   make test   set up .venv and run the test suite
VENV   ?= .venv
PYTHON ?= python3
BIN    := $(VENV)/bin
OUT    ?= out/demo

.PHONY: setup demo test bench samples figure clean

$(BIN)/.installed: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	# torch is pinned to the CPU build (torch==2.13.0); an unpinned torch would pull a multi-GB CUDA build.
	$(BIN)/python -m pip install --quiet "torch==2.13.0"
	$(BIN)/python -m pip install --quiet -e ".[test]"
	touch $@

# The official nuScenes devkit is a test oracle only (it pins numpy<2, so it is installed without its
# dependencies, plus the light ones it really imports); the tests require it under `make test`.
$(BIN)/.devkit: $(BIN)/.installed
	$(BIN)/python -m pip install --quiet --no-deps "nuscenes-devkit==1.2.0"
	$(BIN)/python -m pip install --quiet cachetools descartes fire matplotlib scikit-learn "shapely~=2.0.3" \
		parameterized pycocotools pillow pandas "motmetrics<1.5"
	touch $@

setup: $(BIN)/.installed

demo: setup
	$(BIN)/streetaug batch --cameras CAM_FRONT,CAM_FRONT_LEFT --out $(OUT)
	$(BIN)/streetaug insert --scene sample-sunny --debug --out $(OUT)/insert-sunny
	$(BIN)/streetaug predict-light --scene sample-lowsun --out $(OUT)/light-lowsun
	$(BIN)/streetaug batch --dataroot examples/nuscenes-sequence --version v1.0-sequence --tracks 3 --out $(OUT)/tracks
	$(BIN)/streetaug batch --cameras CAM_FRONT --n-objects 3 --classes pedestrian,bicycle,traffic_cone,barrier,truck,bus \
		--out $(OUT)/classes
	@echo
	@echo "Outputs:"
	@echo "  $(OUT)/                            a nuScenes dataset: NuScenes(version='v1.0-samples', dataroot='$(OUT)')"
	@echo "  $(OUT)/samples/<CAMERA>/*.jpg      augmented images of every bundled scene"
	@echo "  $(OUT)/labels/<CAMERA>/*.json      their 3D labels; summary.json, augment_log.jsonl, contact_sheet.png"
	@echo "  $(OUT)/samples/LIDAR_TOP/*.pcd.bin the LiDAR sweeps with the inserted cars in them"
	@echo "  $(OUT)/insert-sunny/               one insertion with mask.png and shadow.exr"
	@echo "  $(OUT)/light-lowsun/               lighting.json, envmap_camera.exr, preview.png"
	@echo "  $(OUT)/tracks/                     up to 3 tracks through the bundled sequence scene (5 keyframes): a nuScenes"
	@echo "                                     dataset with linked instances and velocities; tracks_sheet.png"
	@echo "  $(OUT)/classes/                    pedestrians, bicycles, cone lines, barriers, trucks and buses in CAM_FRONT"

test: setup $(BIN)/.devkit
	STREETAUG_REQUIRE_DEVKIT=1 $(BIN)/pytest -q -n 2 --dist loadfile  # one file per process: module fixtures built once

bench: setup
	$(BIN)/python benchmarks/bench_render.py

samples: setup
	$(BIN)/streetaug make-samples --out examples/nuscenes-samples
	$(BIN)/streetaug make-samples --sequence --out examples/nuscenes-sequence

figure: setup
	$(BIN)/python examples/readme_figure.py

clean:
	rm -rf $(VENV) out .pytest_cache
