"""The user store: the one folder where what a user builds or records is kept, outside the package.

The package's stored scenes and references are read-only data: an installed
wheel may sit in a read-only site-packages, and a checkout's are tracked
files. What ``cbox reference build`` and ``cbox reference verify`` make of
them goes here instead (its layout: :mod:`cornell_harness.store.references`).

The folder is, first found: the ``--home DIR`` of the command, ``$CBOX_HOME``,
else the platform's user data folder (``platformdirs.user_data_dir``:
``~/.local/share/cornell-harness`` on Linux). It is created on the first write.
"""

from __future__ import annotations

import os
from pathlib import Path

#: The environment variable naming the user store.
HOME_VARIABLE = "CBOX_HOME"
#: The application's name in the platform's user data folder.
APP_NAME = "cornell-harness"


def user_home(home: str | Path | None = None) -> Path:
    """The user store's folder: ``home`` (a command's ``--home``), else ``$CBOX_HOME``, else the platform's."""
    if home:
        return Path(home).expanduser().absolute()
    if env := os.environ.get(HOME_VARIABLE):
        return Path(env).expanduser().absolute()
    import platformdirs  # only where neither names one

    return Path(platformdirs.user_data_dir(APP_NAME, appauthor=False))


def home_source(home: str | Path | None = None) -> str:
    """Where :func:`user_home` found the folder: ``--home``, ``$CBOX_HOME`` or ``the platform's user data folder``."""
    if home:
        return "--home"
    return f"${HOME_VARIABLE}" if os.environ.get(HOME_VARIABLE) else "the platform's user data folder"
