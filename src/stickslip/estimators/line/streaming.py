"""Training batches streamed from a dataset's chunks, with detector effects drawn on the fly.

A training set need not fit in memory: :class:`LineBatches` reads the forces a chunk of
consecutive rows at a time (:class:`~stickslip.traces.dataset.Rows`: an HDF5 file, a
Zarr store, or an in-memory array cut into chunks of
:data:`~stickslip.traces.dataset.ROW_CHUNK` rows; one code path for all), and the
loader's workers corrupt and map each batch
(:func:`~stickslip.estimators.line.training.prepare_batch`, passed in) while the network
trains on the previous one.

Order. Every epoch each worker visits its share of the chunks (chunk ``i`` goes to
worker ``i mod W``) in a fresh random order and passes their training rows through a
shuffle buffer of :attr:`StreamSettings.shuffle_rows` rows (at least two chunks), from
which batches are drawn at random. Every training row is read exactly once per epoch.

Why a buffer of 8192 rows is enough. Rows stored next to each other may be alike (a grid
sweep writes neighbouring parameters into one chunk), so a batch must not come from a
few chunks. Visiting chunks in random order removes the file's large-scale order; the
buffer then mixes rows of ``R / c`` chunks (``R`` buffer rows, ``c`` rows per chunk). In
the worst case, all rows of a chunk identical, a batch of ``b`` rows holds
``(R / c) (1 - exp(-b c / R))`` distinct chunks: 81 of 128 rows with the defaults and
64-row chunks (an effective batch of 81), against 128 for a full shuffle; the buffer
keeps refilling as it drains, so consecutive batches overlap no more than under a full
shuffle. The project's randomised sets draw every row independently, for which storage
order carries no information at all. The buffer costs ``R x pixels`` floats (16 MB at
512 px in float32) per worker, whatever the size of the set; a set smaller than the
buffer is shuffled whole.

Pristine lines (see :mod:`~stickslip.estimators.line.training`) are drawn, with
replacement, from a ring of the last :data:`PRISTINE_POOL_ROWS` flat-substrate training
rows a worker read (the chunks arrive in random order, so the ring is a random sample of
the set's flat rows); they replace the first rows of a batch, which sit this epoch out,
as in-memory training did.

Reproducibility. Worker ``w`` of member ``k`` in epoch ``e`` draws everything (chunk
order, buffer, pristine rows, detector effects, crops) from its own stream
``default_rng([seed, STREAM, k, e, w])``, so a run is reproducible for a given number of
workers; ``num_workers=0`` (batches made in the training process) gives the batches of
one worker.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from torch.utils.data import DataLoader, IterableDataset, get_worker_info

from stickslip.traces.dataset import Rows

#: Key of the training batches' random streams (the validation draws use 999).
STREAM = 31
#: Flat-substrate rows a worker keeps to draw pristine lines from.
PRISTINE_POOL_ROWS = 1024

Batch = tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]


@dataclass(frozen=True)
class StreamSettings:
    """How training batches are read (not how the model is trained: kept out of the
    model file's training config, recorded in its report).

    ``num_workers`` loader processes (0: in the training process; same batches as 1),
    ``shuffle_rows`` rows in each worker's shuffle buffer, ``steps_per_epoch`` a cap on
    the batches of an epoch (None: one pass over the training rows; a cap reads only
    the chunks it needs).
    """

    num_workers: int = 1
    shuffle_rows: int = 8192
    steps_per_epoch: int | None = None


def read_chunks(
    source: Rows, chunks: Iterable[tuple[int, int]], keep: np.ndarray
) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """The rows marked in ``keep`` of each chunk ``[start, stop)``, in the order given, as
    (row indices, rows); chunks without such rows are skipped."""
    for s, e in chunks:
        sel = keep[s:e]
        if sel.any():
            yield np.arange(s, e)[sel], source.read(s, e)[sel]


def shuffle_buffer(
    blocks: Iterable[tuple[np.ndarray, np.ndarray]],
    capacity: int,
    size: int,
    rng: np.random.Generator,
) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """Blocks of ``size`` rows drawn at random from a buffer of ``capacity`` rows that
    ``blocks`` keeps filling; the buffer is emptied at the end (the last block may be
    short). Every row in ``blocks`` comes out exactly once."""
    idx: np.ndarray | None = None
    rows: np.ndarray | None = None
    n = 0

    def take(k: int) -> tuple[np.ndarray, np.ndarray]:
        nonlocal n
        pick = rng.choice(n, k, replace=False)
        out = idx[pick], rows[pick]  # fancy indexing copies: safe to overwrite below
        tail = np.zeros(k, bool)
        tail[pick[pick >= n - k] - (n - k)] = True
        holes, movers = np.sort(pick[pick < n - k]), np.flatnonzero(~tail) + (n - k)
        idx[holes], rows[holes] = idx[movers], rows[movers]
        n -= k
        return out

    for bi, br in blocks:
        if rows is None:  # room for a full buffer and one more block
            cap = max(capacity, size) + bi.size
            idx, rows = np.empty(cap, np.int64), np.empty((cap, br.shape[1]), br.dtype)
        if n + bi.size > rows.shape[0]:  # a block larger than the first one
            idx = np.resize(idx, n + bi.size)
            rows = np.concatenate([rows[:n], np.empty((bi.size, rows.shape[1]), rows.dtype)])
        idx[n : n + bi.size], rows[n : n + bi.size] = bi, br
        n += bi.size
        while n >= max(capacity, size):
            yield take(size)
    while n:
        yield take(min(size, n))


class _Ring:
    """The last ``capacity`` rows offered (a pool to draw pristine lines from)."""

    def __init__(self, capacity: int):
        self.capacity, self.n, self.at = capacity, 0, 0
        self.idx: np.ndarray | None = None
        self.rows: np.ndarray | None = None

    def offer(self, idx: np.ndarray, rows: np.ndarray) -> None:
        if self.rows is None:
            self.idx = np.empty(self.capacity, np.int64)
            self.rows = np.empty((self.capacity, rows.shape[1]), rows.dtype)
        for i, r in zip(idx[-self.capacity :], rows[-self.capacity :], strict=True):
            self.idx[self.at], self.rows[self.at] = i, r
            self.at = (self.at + 1) % self.capacity
            self.n = min(self.n + 1, self.capacity)


class LineBatches(IterableDataset):
    """One epoch of training batches of one ensemble member, for a torch DataLoader
    (``batch_size=None``: items are whole batches).

    Each item is ``(X, C, rows, observed)``: the corrupted, mapped inputs and their
    conditioning (as :func:`prepare`, i.e. ``prepare_batch``, returns them), the source
    rows (for the targets, which stay in the training process) and the corrupted traces'
    means. Set :attr:`epoch` before iterating.

    Parameters
    ----------
    source : Rows
        The forces, read a chunk at a time.
    train : ndarray of int
        Training rows.
    flat : ndarray of bool (N,)
        Flat-substrate rows (candidates for pristine lines).
    prepare : callable
        ``prepare(force_nN, rows, keep_clean, rng) -> (X, C, observed)``.
    batch_size, pristine_fraction, seed, member : batch size, fraction of pristine lines,
        the run's seed and the member's index.
    settings : StreamSettings
    """

    def __init__(self, source: Rows, train: np.ndarray, flat: np.ndarray,
                 prepare: Callable[..., tuple[torch.Tensor, torch.Tensor, np.ndarray]],
                 batch_size: int, pristine_fraction: float, seed: int, member: int,
                 settings: StreamSettings = StreamSettings()):  # fmt: skip
        super().__init__()
        self.source, self.prepare, self.settings = source, prepare, settings
        self.keep = np.zeros(source.shape[0], bool)
        self.keep[train] = True
        self.flat = np.asarray(flat, bool) & self.keep
        self.batch_size, self.pristine_fraction = int(batch_size), float(pristine_fraction)
        self.seed, self.member, self.epoch = int(seed), int(member), 0
        self.workers = max(1, int(settings.num_workers))
        self.capacity = max(int(settings.shuffle_rows), 2 * source.chunk_rows)

    def shares(self) -> list[list[tuple[int, int]]]:
        """Each worker's chunks: chunk ``i`` to worker ``i mod W``."""
        chunks = self.source.chunks()
        return [chunks[w :: self.workers] for w in range(self.workers)]

    def worker_batches(self) -> list[int]:
        """Batches each worker yields per epoch: its training rows // batch size (one
        short batch when it has fewer rows than a batch; the rest sit the epoch out)."""
        out = []
        for share in self.shares():
            n = int(sum(self.keep[s:e].sum() for s, e in share))
            out.append(max(1, n // self.batch_size) if n else 0)
        return out

    def batches_per_epoch(self) -> int:
        """Steps of an epoch (with the :attr:`StreamSettings.steps_per_epoch` cap)."""
        n = sum(self.worker_batches())
        cap = self.settings.steps_per_epoch
        return n if cap is None else min(n, int(cap))

    def rng(self, worker: int) -> np.random.Generator:
        """The random stream of ``worker`` in this member and epoch."""
        return np.random.default_rng([self.seed, STREAM, self.member, self.epoch, worker])

    def rows(
        self, worker: int, rng: np.random.Generator, pool: _Ring | None = None
    ) -> Iterator[tuple[np.ndarray, np.ndarray]]:
        """The worker's training rows in shuffled blocks of a batch (every row once);
        flat-substrate rows read are offered to ``pool``."""
        share = self.shares()[worker]
        order = [share[i] for i in rng.permutation(len(share))]
        blocks = read_chunks(self.source, order, self.keep)
        if pool is not None:
            blocks = self._tap(blocks, pool)
        return shuffle_buffer(blocks, self.capacity, self.batch_size, rng)

    def _tap(
        self, blocks: Iterable[tuple[np.ndarray, np.ndarray]], pool: _Ring
    ) -> Iterator[tuple[np.ndarray, np.ndarray]]:
        for idx, rows in blocks:
            f = self.flat[idx]
            if f.any():
                pool.offer(idx[f], rows[f])
            yield idx, rows

    def batches(self, worker: int) -> Iterator[Batch]:
        """The batches of ``worker`` in this epoch."""
        rng = self.rng(worker)
        pool = _Ring(PRISTINE_POOL_ROWS)
        count = self.worker_batches()[worker]
        for _, (idx, rows) in zip(range(count), self.rows(worker, rng, pool), strict=False):
            keep = np.zeros(idx.size, bool)
            if pool.n and self.pristine_fraction > 0:
                n_p = int(rng.binomial(idx.size, self.pristine_fraction))
                pick = rng.integers(0, pool.n, n_p)
                idx[:n_p], rows[:n_p] = pool.idx[pick], pool.rows[pick]
                keep[:n_p] = True
            X, C, observed = self.prepare(np.asarray(rows, float), idx, keep, rng)
            yield X, C, torch.from_numpy(idx), torch.from_numpy(np.asarray(observed, float))

    def __iter__(self) -> Iterator[Batch]:
        info = get_worker_info()
        if info is None:  # no loader processes: every share here, interleaved as a
            # loader interleaves its workers' batches
            its = [self.batches(w) for w in range(self.workers)]
            while its:
                for it in list(its):
                    try:
                        yield next(it)
                    except StopIteration:
                        its.remove(it)
            return
        yield from self.batches(info.id)


def batch_loader(batches: LineBatches) -> DataLoader:
    """A DataLoader over ``batches`` with its settings' workers. The source's file is
    closed first, so each worker opens its own."""
    batches.source.close()
    w = batches.settings.num_workers
    kw: dict[str, Any] = {"prefetch_factor": 2} if w > 0 else {}
    # its own generator: the loader's seed draw leaves torch's global stream alone
    return DataLoader(batches, batch_size=None, num_workers=w,
                      generator=torch.Generator().manual_seed(batches.seed), **kw)  # fmt: skip
