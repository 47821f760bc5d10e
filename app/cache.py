"""A small LRU of computed values that computes each key once (the dashboard's views, the
catalogues' status statistics). Caches live on the app's ``ServiceContext``
(``ctx.cache(name, size)``), so they go with the app."""

from __future__ import annotations

import threading
from collections import OrderedDict
from collections.abc import Callable
from typing import Any

__all__ = ["ViewCache"]


class ViewCache:
    """A small thread-safe LRU of computed views (they are pure functions of their key)."""

    def __init__(self, size: int = 64) -> None:
        self.size = size
        self._data: OrderedDict[tuple[Any, ...], Any] = OrderedDict()
        self._lock = threading.Lock()
        self._pending: dict[tuple[Any, ...], threading.Lock] = {}

    def _lookup(self, key: tuple[Any, ...]) -> tuple[bool, Any]:
        with self._lock:
            if key in self._data:
                self._data.move_to_end(key)
                return True, self._data[key]
        return False, None

    def get(self, key: tuple[Any, ...], compute: Callable[[], Any]) -> Any:
        """The cached value of ``key``, computed once even when asked for concurrently
        (the second caller waits for the first one's result)."""
        found, value = self._lookup(key)
        if found:
            return value
        with self._lock:
            pending = self._pending.setdefault(key, threading.Lock())
        with pending:
            found, value = self._lookup(key)
            if found:
                return value
            try:
                value = compute()
            except BaseException:
                with self._lock:
                    self._pending.pop(key, None)
                raise
            with self._lock:
                self._data[key] = value
                self._data.move_to_end(key)
                while len(self._data) > self.size:
                    self._data.popitem(last=False)
                self._pending.pop(key, None)
        return value

    def clear(self) -> None:
        with self._lock:
            self._data.clear()
