"""Registering groups of submodules in order and unregistering them in reverse, even after a failure."""
from __future__ import annotations

from types import ModuleType
from typing import Sequence


class ModuleGroup:
    """Submodules that each have register()/unregister(); a failed register() undoes what it did."""

    def __init__(self, modules: Sequence[ModuleType]) -> None:
        self.modules = tuple(modules)
        self._registered: list[ModuleType] = []

    def register(self) -> None:
        try:
            for module in self.modules:
                module.register()
                self._registered.append(module)
        except BaseException:
            self.unregister()
            raise

    def unregister(self) -> None:
        while self._registered:
            self._registered.pop().unregister()
