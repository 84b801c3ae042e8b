#!/usr/bin/env bash
# Set up cornell-harness on a fresh Debian/Ubuntu machine: system libraries
# (when missing), then a virtual environment in .venv with the project.
# Safe to run again: it only installs what is missing or changed.
#
#   scripts/setup.sh                 # what `cbox demo` needs
#   scripts/setup.sh --tests         # plus the test tools: pytest, Playwright, Debian's chromium, pdflatex, MkDocs
#   CBOX_NO_APT=1 scripts/setup.sh   # never call apt-get (renderers needing
#                                    # missing libraries then report themselves unavailable)
set -euo pipefail
cd "$(dirname "$0")/.."

TESTS=""
for arg in "$@"; do
  case "$arg" in
    --tests) TESTS=1 ;;
    -h|--help) sed -n '2,9p' "$0"; exit 0 ;;
    *) echo "setup: unknown option $arg (see --help)" >&2; exit 2 ;;
  esac
done

say() { printf 'setup: %s\n' "$*" >&2; }

# --- system libraries -------------------------------------------------------
# libllvm19: Mitsuba's fast llvm_ad_rgb variant (needs LLVM >= 17; without it
#            Mitsuba falls back to scalar_rgb).
# libegl1 libgl1 libegl-mesa0 libgl1-mesa-dri libosmesa6: headless OpenGL for pyrender.
# libcairo2: cairosvg's drawing library, for the report's PDF and PNG figures (without it the
#            report still writes its SVG figures, and says why the others are missing).
need_pkgs=()
have_lib() { ldconfig -p 2>/dev/null | grep -q "$1"; }
have_llvm17() { ls /usr/lib/*/libLLVM*.so* /usr/lib/llvm-*/lib/libLLVM*.so* 2>/dev/null \
  | grep -Eq 'libLLVM(-|\.so\.)(1[7-9]|[2-9][0-9])'; }
have_llvm17 || need_pkgs+=(libllvm19)
have_lib 'libEGL\.so\.1' || need_pkgs+=(libegl1)
have_lib 'libGL\.so\.1' || need_pkgs+=(libgl1)
have_lib 'libEGL_mesa\.so\.0' || need_pkgs+=(libegl-mesa0)
ls /usr/lib/*/dri/swrast_dri.so >/dev/null 2>&1 || need_pkgs+=(libgl1-mesa-dri)
have_lib 'libOSMesa\.so' || need_pkgs+=(libosmesa6)
have_lib 'libcairo\.so\.2' || need_pkgs+=(libcairo2)
# chromium: the report's browser test (Playwright drives Debian's build;
# Playwright's own browser download is not used).
[[ -n $TESTS ]] && ! command -v chromium >/dev/null 2>&1 && need_pkgs+=(chromium)
# gcc and libc6-dev (cc and the C headers; libc6-dev is only a recommendation of gcc): the test that
# compiles examples/c-renderer/ao.c and gates it (tests/examples/test_c_renderer.py).
[[ -n $TESTS ]] && ! command -v cc >/dev/null 2>&1 && need_pkgs+=(gcc libc6-dev)
# pdflatex and booktabs.sty (in texlive-latex-recommended): the test that compiles OUT/summary.tex
# (tests/reports/test_summary_files.py; skipped without them). Small: 48 MB of downloads, 147 MB installed,
# about 30 s to install with --no-install-recommends (Debian 12).
[[ -n $TESTS ]] && ! command -v pdflatex >/dev/null 2>&1 && need_pkgs+=(texlive-latex-base texlive-latex-recommended)

if ((${#need_pkgs[@]})); then
  if [[ -n "${CBOX_NO_APT:-}" ]]; then
    say "missing system packages (not installed, CBOX_NO_APT set): ${need_pkgs[*]}"
  else
    SUDO=""; [[ $(id -u) -ne 0 ]] && SUDO="sudo"
    say "installing system packages: ${need_pkgs[*]}"
    export DEBIAN_FRONTEND=noninteractive
    if ! $SUDO apt-get install -y --no-install-recommends "${need_pkgs[@]}" >/dev/null 2>&1; then
      $SUDO apt-get update -qq && $SUDO apt-get install -y --no-install-recommends "${need_pkgs[@]}" >/dev/null
    fi
  fi
fi

# --- Python environment -----------------------------------------------------
PY=${PYTHON:-python3}
"$PY" -c 'import sys; sys.exit(sys.version_info < (3, 11))' \
  || { say "Python 3.11 or newer is needed (found $("$PY" --version 2>&1))"; exit 1; }
[[ -x .venv/bin/python ]] || { say "creating .venv"; "$PY" -m venv .venv; }

# Reinstall only when the dependency list (or the --tests choice) changed. Every extra (pyproject.toml's
# [all]: our renderers, Mitsuba, LuxCore, pyrender, OIDN, Dask), so that `cbox demo` has every renderer; with
# --tests also the test tools and the docs site's (tests/test_docs_site.py builds it).
extras="[all]"; [[ -n $TESTS ]] && extras="[all,test,docs]"
stamp=.venv/.cbox-installed
sha=$(sha256sum pyproject.toml | cut -d' ' -f1)
want="$sha$extras"
have=$(cat "$stamp" 2>/dev/null || true)
# A test install is a superset of the plain one: it satisfies both.
if [[ $have != "$want" && $have != "$sha[all,test,docs]" ]]; then
  say "installing Python packages into .venv (first run takes a minute)"
  # pip's and setuptools' own chatter (build-backend warnings) goes to a log shown only if something fails,
  # so this script prints only its own lines.
  log=.venv/.cbox-pip.log
  if ! { .venv/bin/python -m pip install -q --upgrade pip && .venv/bin/python -m pip install -q -e ".$extras"; } \
      >"$log" 2>&1 || ! .venv/bin/python -c 'import cornell_harness.cli.app, cornell_harness.renderers.mitsuba3' 2>>"$log"; then
    cat "$log" >&2
    say "installation failed (pip's output above, also in $log)"
    exit 1
  fi
  echo "$want" > "$stamp"
fi
# --- Blender's bpy (the cycles renderer) ------------------------------------------
# Not an extra (pyproject.toml says why: it pins numpy<2) but installed with --tests, without its dependencies,
# so that the cycles tests run: 374 MB to download, 821 MB installed. Its wheels are for Python 3.11 only.
if [[ -n $TESTS ]] && ! .venv/bin/python -c 'import importlib.util, sys; sys.exit(importlib.util.find_spec("bpy") is None)'; then
  bpy_install=$(.venv/bin/python -c 'from cornell_harness.extras import COMMANDS; print(COMMANDS["cycles"])')
  say "installing Blender for the cycles renderer's tests: $bpy_install (374 MB download)"
  if ! eval ".venv/bin/python -m $bpy_install -q" >>.venv/.cbox-pip.log 2>&1; then
    say "installing bpy failed (see .venv/.cbox-pip.log; wheels exist for Python 3.11 only): the cycles tests will fail"
  fi
fi
# --- numba kernels -----------------------------------------------------------
# Compiled once into numba's on-disk cache (__pycache__), so that the first `cbox demo` does not spend its
# first minute compiling (BENCHMARKS.md: the demo 3:42 cold, 2:43 after this). Again only when the sources
# of the kernels changed; a failure here is not setup's: renders compile what they need when first used.
kernels_want=$(cat src/cornell_harness/renderers/*.py src/cornell_harness/renderers/core/*.py src/cornell_harness/evaluate/*.py | sha256sum | cut -d' ' -f1)
if [[ $(cat .venv/.cbox-kernels 2>/dev/null || true) != "$kernels_want" ]]; then
  say "compiling the renderers' kernels into numba's cache (about a minute, once)"
  if .venv/bin/python scripts/compile_kernels.py 2>.venv/.cbox-kernels.log; then
    echo "$kernels_want" > .venv/.cbox-kernels
  else
    say "compiling kernels failed (see .venv/.cbox-kernels.log); renders will compile them when first used"
  fi
fi
say "ready: .venv/bin/cbox --help"
