"""A fence database brought up to date with OpenStreetMap's changes, rebuilding only the sites
they touch, with the fences a whole build of the changed extract writes.

Sites are grouped region by region (:func:`alphafence.fencing.regions.region_labels`): a
region is closed (no feature outside it comes near one inside) and its sites and fences are
made of its features alone, in their canonical order. So an update

1. applies the changes to the store's nodes and ways and names every object whose feature may
   have changed (:func:`alphafence.updating.middle.apply_changes`);
2. reads those objects again, with the build's own reader, from a small extract of them;
3. finds the regions of the old features (before) and of the new ones and the old ones left
   (after), whole, and groups each: the old sites' rows go, the new sites' fences come.
"""

from __future__ import annotations

import dataclasses
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

from alphafence.fencing.pipeline import BuildOptions


@dataclass
class UpdateResult:
    """What an update did.

    Attributes
    ----------
    changes : int
        Objects the change files name.
    touched : int
        OpenStreetMap objects read again.
    removed_features, added_features : int
    features : int
        Restricted features rebuilt (the regions touched, whole).
    sites_removed, sites_added : list of str
        Site ids whose rows went and came.
    rows_removed, rows_added : int
    version : int, optional
        The PostGIS table's new version.
    seconds : dict
    """

    changes: int = 0
    touched: int = 0
    removed_features: int = 0
    added_features: int = 0
    features: int = 0
    sites_removed: list = field(default_factory=list)
    sites_added: list = field(default_factory=list)
    rows_removed: int = 0
    rows_added: int = 0
    version: int | None = None
    seconds: dict = field(default_factory=dict)


def update(store_path, change_paths, target=None, progress=None, stop=None) -> UpdateResult:
    """Apply OpenStreetMap change files to a fence database built with a store.

    Parameters
    ----------
    store_path : str or Path
        The build's ``--store``.
    change_paths : list of str
        ``.osc`` / ``.osc.gz`` files, in the order they apply.
    target : str, optional
        The fences to update (default: the build's output, as the store names it).
    progress : callable, optional
        ``progress(step)`` as each step starts.
    stop : callable, optional
        Called between steps and batches; raises to stop (Ctrl-C): nothing is changed.

    Returns
    -------
    UpdateResult

    Raises
    ------
    InputError
        A change file, the store or the fences cannot be read or written: nothing changed.
    """
    from alphafence.fencefiles.fence_geojson import fence_features
    from alphafence.fencing.fences import fence_sites
    from alphafence.fencing.sites import group_sites
    from alphafence.updating.middle import apply_changes, read_changes
    from alphafence.updating.store import Store
    from alphafence.updating.targets import replace_sites

    def step(name):
        if stop is not None:
            stop()
        if progress is not None:
            progress(name)

    out = UpdateResult()
    t0 = time.perf_counter()
    with Store(store_path) as store:
        rules, options = store.rules(), BuildOptions(**store.meta("options"))
        target = target or store.meta("output")
        step("reading the changes")
        changes = read_changes(change_paths, stop)
        out.changes = len(changes)
        step("applying them to the store")
        touched = apply_changes(store.db, changes, rules.keys)
        sources = {f"{kind}/{i}" for kind, ids in touched.items() for i in ids}
        out.touched = len(sources)
        step("reading the objects they touch")
        fresh = _read_touched(store, touched, changes, sources, rules)
        removed = store.ids_of(sources)
        before = store.region_of(removed)
        old = dict(zip(before, store.features(before)))
        store.remove(removed)
        added = store.add(fresh, options.join_m)
        gone = set(removed)
        step("finding the regions they are in")
        after = store.region_of([*added, *(i for i in before if i not in gone)])
        more = [i for i in after if i not in old and i not in set(added)]
        old.update(zip(more, store.features(more)))
        t1 = time.perf_counter()
        step(f"rebuilding {len(after)} features' sites")
        old_sites = group_sites(list(old.values()), rules, options.join_m)
        sites = group_sites(store.features(after), rules, options.join_m)
        fences = fence_sites(sites, options)
        t2 = time.perf_counter()
        step("writing the fences")
        drop = {s.site_id for s in old_sites} | {s.site_id for s in sites}
        meta = {"updated_with": [*store.meta("changes", []), *changes.files]}
        written = replace_sites(target, drop, fence_features(fences), meta)
        store.set_meta("changes", meta["updated_with"])
        if stop is not None:
            stop()
        store.commit()
    out.removed_features, out.added_features, out.features = len(removed), len(added), len(after)
    out.sites_removed = sorted(s.site_id for s in old_sites)
    out.sites_added = sorted(s.site_id for s in sites)
    out.rows_removed, out.rows_added = written["removed"], written["added"]
    out.version = written["version"]
    t3 = time.perf_counter()
    out.seconds = {"read": t1 - t0, "fence": t2 - t1, "write": t3 - t2, "total": t3 - t0}
    return out


def _read_touched(store, touched, changes, sources, rules):
    """The restricted features of the touched objects as they are after the change, read by
    the build's reader from a small extract of them, inside the build's bbox."""
    from alphafence.updating.middle import write_extract
    from alphafence.zones.features import select_bbox
    from alphafence.zones.osm import read_osm

    origin = store.meta("origin")
    bbox = store.meta("bbox")
    with tempfile.TemporaryDirectory(prefix="alphafence-update-") as tmp:
        path = Path(tmp) / "touched.osm.pbf"
        write_extract(store.db, touched, changes, path)
        features = read_osm(path, rules, [], __import__("collections").Counter())
    features = [dataclasses.replace(f, origin=origin) for f in features if f.source in sources]
    return select_bbox(features, tuple(bbox) if bbox else None)
