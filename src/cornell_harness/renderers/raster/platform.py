"""Getting an OpenGL context without a display: EGL or OSMesa.

PyOpenGL binds to a platform once, when it is first imported, from
``PYOPENGL_PLATFORM``; a process cannot switch later. So the platform is
chosen here before pyrender (and with it PyOpenGL) is imported: the user's
``PYOPENGL_PLATFORM`` if set (``egl`` or ``osmesa`` only), else the platform
whose libraries ``ctypes.util.find_library`` finds; when both are found, EGL
is tried first in a short subprocess (trying it here would bind this process
to it) and OSMesa is used if that fails. :func:`availability` then makes one
context in this process, checks the OpenGL version and caches the verdict
(with a one-line reason when negative) for the life of the process.
"""

from __future__ import annotations

import ctypes.util
import importlib.metadata
import importlib.util
import os
import subprocess
import sys

import numpy as np

_HEADLESS = ("egl", "osmesa")
_INSTALL_HINT = "pip install 'pyrender2>=0.2.2' 'PyOpenGL>=3.1.9'"
_APT_HINT = "apt-get install libegl1 libgl1 libegl-mesa0 libgl1-mesa-dri (EGL) or libosmesa6 (OSMesa)"

#: Run in a subprocess to see whether a platform can create a GL context.
_PROBE = r"""
import os, sys
os.environ["PYOPENGL_PLATFORM"] = sys.argv[1]
import pyrender  # noqa: F401
if sys.argv[1] == "egl":
    from pyrender.platforms import egl
    p = egl.EGLPlatform(8, 8, device=egl.get_device_by_index(int(os.environ.get("EGL_DEVICE_ID", "0"))))
else:
    from pyrender.platforms.osmesa import OSMesaPlatform
    p = OSMesaPlatform(8, 8)
p.init_context()
p.make_current()
from OpenGL.GL import glGetString, GL_RENDERER
print(glGetString(GL_RENDERER).decode())
p.delete_context()
"""


def _libraries_present(platform: str) -> bool:
    if platform == "egl":
        return bool(ctypes.util.find_library("EGL")) and bool(
            ctypes.util.find_library("OpenGL") or ctypes.util.find_library("GL")
        )
    return bool(ctypes.util.find_library("OSMesa"))


def _probe(platform: str) -> str | None:
    """None if ``platform`` can create a context (in a subprocess), else why not."""
    try:
        p = subprocess.run([sys.executable, "-c", _PROBE, platform], capture_output=True, text=True, timeout=120)
    except (OSError, subprocess.SubprocessError) as e:
        return f"{type(e).__name__}: {e}"
    if p.returncode == 0:
        return None
    lines = [ln.strip() for ln in (p.stderr or p.stdout).splitlines() if ln.strip()]
    return lines[-1] if lines else f"exit status {p.returncode}"


def _opengl_platform_in_use() -> str | None:
    """The platform PyOpenGL was already bound to in this process, if any."""
    mod = sys.modules.get("OpenGL.platform")
    plat = getattr(mod, "PLATFORM", None)
    if plat is None:
        return None
    name = type(plat).__name__.lower()
    for p in _HEADLESS:
        if p in name:
            return p
    return name


def choose_platform() -> tuple[str | None, str]:
    """(``egl`` / ``osmesa`` or None, a sentence saying why or why not)."""
    env = os.environ.get("PYOPENGL_PLATFORM")
    if env:
        if env not in _HEADLESS:
            return None, f"PYOPENGL_PLATFORM={env!r}: pyrender renders headless only with 'egl' or 'osmesa'"
        return env, f"PYOPENGL_PLATFORM={env} (set by the user)"
    if "OpenGL.platform" in sys.modules:
        used = _opengl_platform_in_use()
        if used in _HEADLESS:
            return used, f"PyOpenGL was already imported with {used}"
        return None, (f"PyOpenGL was already imported in this process with platform {used!r}; "
                      "set PYOPENGL_PLATFORM=egl or osmesa before it is imported")
    present = [p for p in _HEADLESS if _libraries_present(p)]
    if not present:
        return None, f"no EGL or OSMesa library found; {_APT_HINT}"
    if len(present) == 1:
        return present[0], f"only {present[0]} libraries found"
    failures = []
    for p in present:
        why = _probe(p)
        if why is None:
            return p, f"{p} context works (probed in a subprocess)"
        failures.append(f"{p}: {why}")
    return None, "no headless OpenGL context could be created (" + "; ".join(failures) + ")"


def open_platform(platform: str, width: int = 8, height: int = 8):
    """A current pyrender platform (GL context) for ``platform``."""
    if platform == "egl":
        from pyrender.platforms import egl

        device = egl.get_device_by_index(int(os.environ.get("EGL_DEVICE_ID", "0")))
        plat = egl.EGLPlatform(width, height, device=device)
    else:
        from pyrender.platforms.osmesa import OSMesaPlatform

        plat = OSMesaPlatform(width, height)
    plat.init_context()
    plat.make_current()
    return plat


def _gl_string(name: int) -> str:
    from OpenGL import GL

    s = GL.glGetString(name)
    return s.decode(errors="replace") if isinstance(s, bytes) else str(s)


_AVAILABILITY: tuple[str | None, str | None, dict] | None = None


def availability() -> tuple[str | None, str | None, dict]:
    """(platform, reason it is unavailable or None, GL facts). Computed once per process."""
    global _AVAILABILITY
    if _AVAILABILITY is None:
        try:
            platform, reason, facts = _check_availability()
        except Exception as e:  # never raise from an availability probe
            platform, reason, facts = None, f"availability check failed: {type(e).__name__}: {e}", {}
        if reason is not None:
            reason = " ".join(reason.split())  # one line (GL errors print over several)
        _AVAILABILITY = (platform, reason, facts)
    return _AVAILABILITY


def _check_availability() -> tuple[str | None, str | None, dict]:
    if importlib.util.find_spec("pyrender") is None:
        return None, f"pyrender is not installed; {_INSTALL_HINT}", {}
    platform, why = choose_platform()
    if platform is None:
        return None, why, {}
    os.environ.setdefault("PYOPENGL_PLATFORM", platform)
    try:
        import pyrender
    except Exception as e:
        return None, f"cannot import pyrender with PYOPENGL_PLATFORM={platform}: {type(e).__name__}: {e}", {}
    version = getattr(pyrender, "__version__", "0")
    if _version_tuple(version) < (0, 2) and not hasattr(np, "infty"):
        return None, (f"pyrender {version} uses np.infty, which NumPy {np.__version__} removed; "
                      f"{_INSTALL_HINT} (uninstall pyrender first)"), {}
    try:
        plat = open_platform(platform)
    except Exception as e:
        msg = str(e) or "initialisation failed"
        return None, f"cannot create an OpenGL context with {platform}: {type(e).__name__}: {msg}", {}
    try:
        from OpenGL import GL

        facts = {
            "platform": platform,
            "platform_choice": why,
            "gl_renderer": _gl_string(GL.GL_RENDERER),
            "gl_version": _gl_string(GL.GL_VERSION),
        }
        major = GL.glGetIntegerv(GL.GL_MAJOR_VERSION)
        minor = GL.glGetIntegerv(GL.GL_MINOR_VERSION)
        if (int(major), int(minor)) < (3, 3):
            return None, f"OpenGL {facts['gl_version']} found; pyrender needs 3.3 or newer", facts
    except Exception as e:
        return None, f"OpenGL context unusable with {platform}: {type(e).__name__}: {e}", {}
    finally:
        try:
            plat.delete_context()
        except Exception:
            pass
    return platform, None, facts


def _version_tuple(v: str) -> tuple[int, ...]:
    out = []
    for part in v.split("."):
        digits = "".join(ch for ch in part if ch.isdigit())
        if not digits:
            break
        out.append(int(digits))
    return tuple(out)


def pyrender_distribution() -> str:
    """The installed distribution that provides the ``pyrender`` module, with its version."""
    try:
        names = importlib.metadata.packages_distributions().get("pyrender", [])
    except Exception:
        names = []
    for name in names or ["pyrender2", "pyrender-maintained", "pyrender"]:
        try:
            return f"{name} {importlib.metadata.version(name)}"
        except importlib.metadata.PackageNotFoundError:
            continue
    return "pyrender (unknown distribution)"
