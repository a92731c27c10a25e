"""
Start-up hook of sb3_classic: registers its algorithms with rl-zoo3 when, and only when, ``rl_zoo3`` is imported.

The wheel installs this module and ``_sb3_classic_zoo.pth`` (one line, ``import _sb3_classic_zoo``) at the top of
site-packages; Python's ``site`` runs that line at every interpreter start-up. So this module imports nothing but
``sys`` (already loaded): it puts a finder at the front of ``sys.meta_path`` that answers for the ``rl_zoo3`` package
only, and wraps its loader so that ``sb3_classic.zoo.register()`` runs right after the package has executed. Then
``python -m rl_zoo3.train --algo reinforce``, ``rl_zoo3 train``, ``enjoy``, ``record_video`` and the plots see the
algorithms, and a program that never imports rl_zoo3 imports neither torch nor sb3_classic because of it.

The hook imports no submodule of the command being run (``python -m rl_zoo3.train`` imports the package first, and
runpy warns if ``rl_zoo3.train`` is already in ``sys.modules``). If registration fails (an rl-zoo3 without what it
patches, or any other error), it warns instead of raising, so that the zoo still works for its own algorithms;
``sb3_classic.zoo.register()`` called directly raises.
"""

import sys

# A local constant instead of typing's (importing typing would cost every interpreter start-up); mypy knows the name
TYPE_CHECKING = False
if TYPE_CHECKING:
    from collections.abc import Sequence
    from importlib.machinery import ModuleSpec
    from types import ModuleType

_PACKAGE = "rl_zoo3"


def _register() -> None:
    """Register sb3_classic's algorithms with the rl_zoo3 just imported; warn if that fails."""
    try:
        from sb3_classic.zoo import register

        register()
    # The hook runs inside someone else's `import rl_zoo3`: whatever goes wrong must not break the zoo's own algorithms
    except Exception as error:
        import warnings

        message = f"sb3_classic's algorithms are not available in rl_zoo3: {type(error).__name__}: {error}"
        warnings.warn(message, RuntimeWarning, stacklevel=1)


class _RegisterAfterExec:
    """
    Loader of the ``rl_zoo3`` package: the real one, then ``_register()``. Once the package has executed, the real
    loader is put back in ``module.__loader__`` and ``module.__spec__.loader``.

    :param loader: the loader the other finders returned
    """

    def __init__(self, loader: object) -> None:
        self.loader = loader

    def create_module(self, spec: "ModuleSpec") -> "ModuleType | None":
        create_module = getattr(self.loader, "create_module", None)
        return None if create_module is None else create_module(spec)

    def exec_module(self, module: "ModuleType") -> None:
        self.loader.exec_module(module)  # type: ignore[attr-defined]
        module.__loader__ = self.loader  # type: ignore[assignment]
        if module.__spec__ is not None:
            module.__spec__.loader = self.loader  # type: ignore[assignment]
        _register()

    def __getattr__(self, name: str) -> object:
        # get_resource_reader, get_source, is_package, ...: the real loader's
        return getattr(self.loader, name)


class ZooFinder:
    """``sys.meta_path`` finder that finds ``rl_zoo3`` with the other finders and wraps its loader."""

    #: Marks the finder, so that it is installed once
    sb3_classic_zoo = True

    def find_spec(
        self, fullname: str, path: "Sequence[str] | None" = None, target: "ModuleType | None" = None
    ) -> "ModuleSpec | None":
        """
        :param fullname: the module being imported
        :param path: the parent package's ``__path__`` (None for a top-level module)
        :param target: the module being reloaded, if any
        :return: the spec of ``rl_zoo3`` with the wrapped loader; None for any other module
        """
        if fullname != _PACKAGE:
            return None
        for finder in sys.meta_path:
            find_spec = getattr(finder, "find_spec", None)
            # Skip this finder, and any copy of it (two would ask each other forever)
            if getattr(finder, "sb3_classic_zoo", False) or find_spec is None:
                continue
            spec = find_spec(fullname, path, target)
            if spec is not None:
                break
        else:
            return None
        if spec.loader is not None and hasattr(spec.loader, "exec_module"):
            spec.loader = _RegisterAfterExec(spec.loader)
        return spec


def install() -> None:
    """Put the finder at the front of ``sys.meta_path`` (once); register now if rl_zoo3 is already imported."""
    if not any(getattr(finder, "sb3_classic_zoo", False) for finder in sys.meta_path):
        sys.meta_path.insert(0, ZooFinder())
    if _PACKAGE in sys.modules:
        _register()


install()
