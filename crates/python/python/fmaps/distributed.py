"""Whole collections on a Ray cluster (``pip install fmaps[ray]``).

One Ray task per shape computes its eigenbasis (:func:`fmaps.prepare`);
the prepared shapes go through Ray's object store (numpy arrays, shared,
not copied, between the tasks of one node); then one task per pair runs
:func:`fmaps.match_prepared`. A task whose worker dies is retried (Ray's
``max_retries``), so every pair is reported exactly once. The maps equal
``fmaps batch``'s and ``fmaps match``'s for the same options.

On one machine::

    import ray, fmaps.distributed as fd
    ray.init(num_cpus=8)
    res = fd.match_collection([("a", "b"), ("a", "c")], {"a": "a.off", "b": "b.off", "c": "c.off"})
    res[("a", "b")]["map_ab"]

On a cluster: ``ray start --head`` on one node, ``ray start
--address=HEAD:6379`` on the others (each with fmaps installed and the
meshes readable at the same paths, or pass :class:`fmaps.Mesh` objects
instead of paths), then ``ray.init(address="auto")`` before calling
:func:`match_collection` on the head node.
"""

import sys
import time

import fmaps


def _ray():
    try:
        import ray
    except ImportError as e:  # pragma: no cover - depends on the environment
        raise ImportError("fmaps.distributed needs Ray: pip install 'fmaps[ray]'") from e
    return ray


def match_collection(
    pairs,
    meshes,
    *,
    k_process=200,
    area_normalize=True,
    threads_per_task=1,
    max_retries=3,
    progress=True,
    on_result=None,
    **match_options,
):
    """Matches every pair of ``pairs`` (``(name_a, name_b)``) among
    ``meshes`` (name -> mesh file path or :class:`fmaps.Mesh`) on the Ray
    cluster ``ray.init`` connected to (a local one is started if none).

    ``match_options`` are :func:`fmaps.match_prepared`'s (``refine``,
    ``k``, ``w_orient``, ``mirrored``, ``non_isometric``, ``starts``). Each shape's eigenbasis
    is computed once. Returns ``{(name_a, name_b): dict}`` with ``map_ab``
    (for each vertex of A a vertex of B, 0-based), ``c_ba``,
    ``orientation``, ``quality``, ``times`` and ``refiner``. ``on_result``,
    if given, is called with ``(pair, dict)`` as each pair finishes (in
    completion order); ``progress`` prints a count to stderr.
    """
    ray = _ray()
    if not ray.is_initialized():
        ray.init()
    pairs = [(str(a), str(b)) for a, b in pairs]
    names = sorted({n for p in pairs for n in p})
    missing = [n for n in names if n not in meshes]
    if missing:
        raise fmaps.FmapsError(f"no mesh given for {missing[:5]}")

    @ray.remote(num_cpus=threads_per_task, max_retries=max_retries)
    def prepare(mesh):
        if not isinstance(mesh, fmaps.Mesh):
            mesh = fmaps.Mesh.load(mesh)
        return fmaps.prepare(mesh, k_process=k_process, area_normalize=area_normalize, threads=threads_per_task)

    @ray.remote(num_cpus=threads_per_task, max_retries=max_retries)
    def match(pa, pb):
        r = fmaps.match_prepared(pa, pb, threads=threads_per_task, **match_options)
        return {
            "map_ab": r.map_ab,
            "c_ba": r.c_ba,
            "orientation": r.orientation,
            "quality": dict(r.quality),
            "times": dict(r.times),
            "refiner": r.refiner,
        }

    prepared = {n: prepare.remote(meshes[n]) for n in names}
    pending = {match.remote(prepared[a], prepared[b]): (a, b) for a, b in pairs}
    results = {}
    start = time.perf_counter()
    while pending:
        done, _ = ray.wait(list(pending), num_returns=1)
        for ref in done:
            pair = pending.pop(ref)
            value = ray.get(ref)
            results[pair] = value
            if on_result is not None:
                on_result(pair, value)
            if progress:
                print(
                    f"\rfmaps: {len(results)}/{len(pairs)} pairs, {time.perf_counter() - start:.0f} s",
                    end="" if pending else "\n",
                    file=sys.stderr,
                    flush=True,
                )
    return results
