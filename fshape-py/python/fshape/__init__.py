# Functional shapes (meshes carrying a signal) and their metamorphoses.
#
# The compiled module `fshape._fshape` holds everything; this package
# re-exports it and adds the two type aliases the functions' annotations
# use. The stub beside this file (`__init__.pyi`) documents every name and
# mypy's stubtest checks it against the package (scripts/python-test.sh).

from os import PathLike
from typing import Any, Callable, Mapping, Optional, Union

from ._fshape import *  # noqa: F403
from ._fshape import Config, __doc__  # noqa: F401
from ._fshape import __all__ as _compiled

ConfigLike = Union[Config, Mapping[str, Any], str, "PathLike[str]"]
Progress = Callable[[dict[str, Any]], Optional[bool]]

__all__ = [*_compiled, "ConfigLike", "Progress"]
