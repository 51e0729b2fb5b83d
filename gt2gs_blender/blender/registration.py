"""Registering groups of submodules in order and unregistering them in reverse, even after a failure."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from types import ModuleType


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


class ClassesWithMenu:
    """Blender classes plus one menu entry (a draw function appended to a menu type), registered
    together and removed in reverse; ``menu`` is the name of a ``bpy.types`` menu, resolved at register."""

    def __init__(self, classes: Sequence[type], menu: str, draw: Callable) -> None:
        self.classes, self.menu, self.draw = tuple(classes), menu, draw

    def register(self) -> None:
        import bpy

        for cls in self.classes:
            bpy.utils.register_class(cls)
        getattr(bpy.types, self.menu).append(self.draw)

    def unregister(self) -> None:
        import bpy

        getattr(bpy.types, self.menu).remove(self.draw)
        for cls in reversed(self.classes):
            bpy.utils.unregister_class(cls)
