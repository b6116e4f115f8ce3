"""The build's side of updates: ``alphafence build --store FILE`` keeps, beside the fences,
what ``alphafence update`` needs (:mod:`alphafence.updating.store`), written beside its path
and moved over once complete."""

from __future__ import annotations

import dataclasses
import os
from importlib import resources
from pathlib import Path

from alphafence.errors import InputError
from alphafence.zones.database import OSM_SUFFIXES


def rules_text(path) -> str:
    """The text of the rules a build reads (the shipped ones when ``path`` is None)."""
    if path is None:
        return resources.files("alphafence").joinpath("data/rules.toml").read_text(encoding="utf-8")
    return Path(path).read_text(encoding="utf-8")


class StoreWriter:
    """A store being written by a build.

    Parameters
    ----------
    path : str
        Where the store goes.
    databases : list of str
        The build's databases: one OpenStreetMap extract.
    rules : Rules
    rules_path : str, optional
    options : BuildOptions
    bbox : tuple, optional
    output : str
        The fences the updates will change (a file, or a PostGIS table).
    """

    def __init__(self, path, databases, rules, rules_path, options, bbox, output):
        from alphafence.updating.store import Store

        if len(databases) != 1 or not str(databases[0]).lower().endswith(OSM_SUFFIXES):
            raise InputError(path, "--store keeps an OpenStreetMap extract's build: give one "
                             ".osm.pbf (or .osm) database")  # fmt: skip
        self.path = Path(path)
        self.tmp = self.path.with_name(f".{self.path.name}.{os.getpid()}.tmp")
        self.tmp.unlink(missing_ok=True)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.database = str(databases[0])
        self.keys = rules.keys
        self.join_m = options.join_m
        self.store = Store(self.tmp, create=True)
        meta = {"rules_text": rules_text(rules_path), "rules": rules.source,
                "options": dataclasses.asdict(options), "bbox": list(bbox) if bbox else None,
                "origin": self.database, "output": str(output)}  # fmt: skip
        for key, value in meta.items():
            self.store.set_meta(key, value)

    def add(self, features):
        """Keep a batch of the build's restricted features."""
        self.store.add(features, self.join_m)

    def finish(self, progress=None):
        """Keep the extract's nodes and ways (``progress(nodes)`` as they are kept), then move
        the store into place."""
        from alphafence.updating.middle import load_middle

        try:
            load_middle(self.store.db, self.database, self.keys, progress)
            self.store.commit()
            self.store.close()
            os.replace(self.tmp, self.path)
        finally:
            self.abort()

    def abort(self):
        """Drop the store being written (the one at the path, if any, stays)."""
        try:
            self.store.close()
        except Exception:  # noqa: BLE001 - closed already
            pass
        self.tmp.unlink(missing_ok=True)
