"""Whole-line models: a 1D CNN over the mapped trace with Gaussian heads, and ensembles.

Where the paper's MLP reads windows of a trace, these models read the whole line.

Input. A trace on lattice ``a`` is mapped onto the reference lattice ``a0`` exactly as
for the window models (:mod:`stickslip.estimators.window.inference`): positions divided by
``s = a / a0``, forces unchanged, then resampled (pixel means) onto the reference pixel,
so a lattice period always spans the same number of pixels. The network sees two
channels, the force and its pixel-to-pixel difference, plus two conditioning scalars
(``s - 1`` and ``ln(v / v0)``), so that thermal activation, which the mapping does not
carry over, is learned rather than ignored. Any line of at least ``min_pixels`` works:
global average and max pooling make the network length-agnostic.

Output. For each target (``F_mean_nN`` as a correction to the trace's own mean, which
is exact on a clean line but carries any offset drift; ``ln U0'``, ``ln K'``, ``ln eta``
with ``U0 = U0' s`` and ``K = K' / s``) a mean and a log-variance in standardised units:
trained with the Gaussian negative log-likelihood, each member reports how sure it is.
An ensemble of members gives the predictive mean and variance (mean of the members'
variances plus the variance of their means). Held-out simulations calibrate it, per
target and per class of line (:class:`SpreadClasses`: quiet lines, as simulations are,
need other factors than noisy ones): the calibrated spread is ``c * sd ** gamma``, a
quantile regression of the 95 % error on the ensemble's own spread (``gamma = 1`` is a
plain scale factor; ``gamma > 1`` where the networks are surer than they should be on
hard lines and less sure than they could be on easy ones). The errors have heavier
tails than a Gaussian's, so the intervals at other levels take the calibration lines'
own distribution of standardised errors (:meth:`LineEnsemble.z_at`).

Expert input (optional). The paper's window MLP, trained on clean simulations, is very
precise on a clean line like its training ones and wrong on a corrupted one. A model
with an ``expert`` reads that MLP's estimate of the line (:func:`expert_inputs`: the
mean over its windows of U0', K' and the implied eta, with their spread over windows)
beside the CNN features, and outputs, per target, a gate ``g`` in (0, 1) with the
mean ``m + g (e - m)`` (``m`` the CNN's own estimate, ``e`` the expert's). The gate is
learned on the randomised training lines, so the network decides from the line itself
when the expert can be trusted; its spread head sees the expert too.
"""

from __future__ import annotations

import copy
from dataclasses import asdict, dataclass, field, replace

import numpy as np
import torch
from torch import nn

from stickslip.conditions import GRAPHITE, TEMPERATURE_TOLERANCE_K, Reference
from stickslip.estimators.calibration import (
    SHAPE_LEVELS,
    Z68,
    SpreadClasses,
    gaussian_z,
    lognormal_std,
)
from stickslip.estimators.evidence import line_evidence, line_evidence_batch, local_evidence
from stickslip.estimators.mapping import to_reference
from stickslip.estimators.noise import log_noise_ratio
from stickslip.estimators.offsets import (
    CompressionPrior,
    OffsetPrior,
    compression_moment,
    friction_bounds,
)
from stickslip.estimators.window.inference import predict_windows
from stickslip.estimators.window.modelfile import TrainedModel
from stickslip.units import eta_from

TARGETS = ("F_mean_nN", "log_U0_ref", "log_K_ref", "log_eta")
INFER_CHUNK = 256
N_EXPERT = 5  # expert inputs: U0', K', eta estimates and the windows' spread of U0', K'


@dataclass(frozen=True)
class LineSpec:
    """How a trace becomes a line-model input (saved in the model file)."""

    lattice_nm: float = GRAPHITE.lattice_nm
    pixel_nm: float = GRAPHITE.pixel_nm
    velocity_nm_per_s: float = GRAPHITE.velocity_nm_per_s
    temperature_K: float = GRAPHITE.temperature_K
    force_scale_nN: float = 5.0
    slope_scale_nN: float = 1.0
    crop: int = 352
    min_pixels: int = 64
    #: the members read the temperature as a third conditioning scalar (models trained
    #: over a range of temperatures); else they assume ``temperature_K``
    condition_temperature: bool = False
    #: the temperatures the model was trained over (K; None: ``temperature_K`` only)
    temperature_range_K: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        if self.temperature_range_K is not None:  # a list, when read back from a file
            object.__setattr__(self, "temperature_range_K",
                               tuple(float(t) for t in self.temperature_range_K))  # fmt: skip

    @classmethod
    def for_temperatures(cls, temperature_K: np.ndarray | None) -> LineSpec:
        """The spec of a model trained on lines at these temperatures: one that reads the
        temperature where they span more than :data:`TEMPERATURE_TOLERANCE_K`, else the
        default (the reference temperature)."""
        if temperature_K is None:
            return cls()
        T = np.asarray(temperature_K, float)
        if float(np.ptp(T)) <= TEMPERATURE_TOLERANCE_K:
            return cls()
        return cls(condition_temperature=True,
                   temperature_range_K=(float(T.min()), float(T.max())))  # fmt: skip

    def trained_at(self, temperature_K: float) -> bool:
        """Whether the model was trained at (or over a range that holds) this temperature."""
        lo, hi = self.temperature_range_K or (self.temperature_K, self.temperature_K)
        return lo - TEMPERATURE_TOLERANCE_K <= temperature_K <= hi + TEMPERATURE_TOLERANCE_K

    def to_dict(self) -> dict:
        return asdict(self)

    @property
    def reference(self) -> Reference:
        """The reference conditions of the model (lattice, pixel, velocity, temperature)."""
        return Reference(self.lattice_nm, self.pixel_nm, self.velocity_nm_per_s,
                         self.temperature_K)  # fmt: skip


def map_line(x_nm: np.ndarray, force_nN: np.ndarray, lattice_nm: float, spec: LineSpec):
    """Mapped, resampled line on the reference lattice and pixel (1-D array)."""
    return to_reference(x_nm, force_nN, lattice_nm, spec.reference)


def line_groups(x_nm: list[np.ndarray], lattice_nm: np.ndarray) -> list[np.ndarray]:
    """Indices of the traces that share their positions and lattice, one array per group
    (in order of first appearance): the lines of one scan share both, so each group is
    mapped and summarised as one 2-D array instead of line by line."""
    groups: dict[tuple, list[int]] = {}
    for i, (x, a) in enumerate(zip(x_nm, lattice_nm, strict=True)):
        groups.setdefault((float(a), np.asarray(x, float).tobytes()), []).append(i)
    return [np.array(g) for g in groups.values()]


def line_inputs(lines: list[np.ndarray], spec: LineSpec, length: int | None = None,
                rng: np.random.Generator | None = None) -> torch.Tensor:  # fmt: skip
    """Stack lines into a (B, 2, L) tensor: scaled force and scaled pixel difference.

    ``length`` (default: the shortest line) is the window taken from each line: a random
    crop when ``rng`` is given (training), else the centred one. Lines shorter than it
    are padded by repeating them periodically (a stick-slip line is nearly periodic).
    """
    L = min(f.size for f in lines) if length is None else int(length)

    def window(f: np.ndarray) -> np.ndarray:
        if f.size < L:
            f = np.resize(f, L)
        start = (f.size - L) // 2 if rng is None else int(rng.integers(0, f.size - L + 1))
        return f[start : start + L]

    # inference batches lines of one length, taken whole: no call per line
    whole = rng is None and all(f.size == L for f in lines)
    W = np.stack(lines if whole else [window(f) for f in lines])
    X = np.empty((len(lines), 2, L), np.float32)
    X[:, 0] = W / spec.force_scale_nN
    X[:, 1, 0] = 0.0
    X[:, 1, 1:] = np.diff(W, axis=1) / spec.slope_scale_nN
    return torch.from_numpy(X)


def input_force_nN(X: torch.Tensor, spec: LineSpec) -> np.ndarray:
    """The force channel of stacked inputs (:func:`line_inputs`) back in nN, (B, L)."""
    return X[:, 0].numpy().astype(np.float64) * spec.force_scale_nN


def n_conditions(spec: LineSpec) -> int:
    """How many conditioning scalars a model of this spec reads."""
    return 3 if spec.condition_temperature else 2


def conditioning(lattice_nm, velocity_nm_per_s, spec: LineSpec,
                 temperature_K=None) -> torch.Tensor:  # fmt: skip
    """Conditioning scalars (B, 2): lattice ratio - 1 and ln of the velocity ratio; with
    ``spec.condition_temperature``, (B, 3) with the temperature ratio - 1 (``None``: the
    reference temperature)."""
    cols = [np.asarray(lattice_nm, float) / spec.lattice_nm - 1.0,
            np.log(np.asarray(velocity_nm_per_s, float) / spec.velocity_nm_per_s)]  # fmt: skip
    if spec.condition_temperature:
        T = spec.temperature_K if temperature_K is None else temperature_K
        cols.append(np.asarray(T, float) / spec.temperature_K - 1.0)
    return torch.from_numpy(np.column_stack(np.broadcast_arrays(*cols)).astype(np.float32))


class PackedBody:
    """A folded convolution stack (``Conv1d``, ``ReLU``, ...) run through oneDNN with its
    weights and activations in oneDNN's blocked layout.

    ``nn.Conv1d`` converts every layer's input and output between torch's layout and
    oneDNN's; for these small layers that costs as much as the arithmetic. Kept blocked
    from the first layer to the last, the stack runs about twice as fast on a CPU, with
    the same arithmetic (tests/estimators/line/test_line.py compares the two).
    Inference only: no gradients flow through it.
    """

    def __init__(self, layers: list[tuple]):
        self.layers = layers

    @classmethod
    def of(cls, body: nn.Sequential) -> PackedBody | None:
        """The packed form of ``body``, or None where it does not apply (no oneDNN in
        this torch build, or layers other than alternating ``Conv1d`` and ``ReLU``)."""
        mods = list(body)
        pairs = list(zip(mods[::2], mods[1::2], strict=False))
        if (not torch.backends.mkldnn.is_available() or len(mods) % 2
                or not all(isinstance(c, nn.Conv1d) and isinstance(r, nn.ReLU)
                           for c, r in pairs)):  # fmt: skip
            return None
        layers = []
        for conv, _ in pairs:
            if conv.bias is None or conv.padding_mode != "zeros":
                return None
            layers.append((conv.weight.detach().to_mkldnn(), conv.bias.detach().to_mkldnn(),
                           conv.padding, conv.stride, conv.dilation, conv.groups))  # fmt: skip
        return cls(layers)

    def __call__(self, x: torch.Tensor) -> torch.Tensor:
        h = x.contiguous().to_mkldnn()
        for w, b, padding, stride, dilation, groups in self.layers:
            h = torch.mkldnn_convolution(h, w, b, padding, stride, dilation, groups).relu_()
        return h.to_dense()


class LineCNN(nn.Module):
    """Strided 1D CNN, global mean+max pooling, conditioning, Gaussian heads; with
    ``n_expert`` > 0, expert inputs and a gate per target (see the module notes).

    ``spread_hidden`` > 0 gives the log-variances a head of their own (one hidden layer
    of that width) instead of rows of the means' head: the spread then spans its own
    range of scales (a pristine line's variance is ~1e3 times below a noisy one's)
    without sharing a hidden layer shaped for the means.
    """

    def __init__(self, channels=(16, 32, 48, 64), n_cond: int = 2, n_targets: int = 4,
                 hidden: int = 128, n_expert: int = 0, spread_hidden: int = 0):  # fmt: skip
        super().__init__()
        layers: list[nn.Module] = []
        cin = 2
        for i, c in enumerate(channels):
            k = 7 if i == 0 else 5
            layers += [nn.Conv1d(cin, c, k, stride=2, padding=k // 2), nn.BatchNorm1d(c),
                       nn.ReLU()]  # fmt: skip
            cin = c
        self.body = nn.Sequential(*layers)
        n_in = 2 * cin + n_cond + n_expert
        # output rows: means, [log-variances], [gates]
        n_out = (1 + (spread_hidden == 0) + (n_expert > 0)) * n_targets
        self.head = nn.Sequential(nn.Linear(n_in, hidden), nn.ReLU(), nn.Linear(hidden, n_out))
        self.spread = None
        if spread_hidden:
            self.spread = nn.Sequential(nn.Linear(n_in, spread_hidden), nn.ReLU(),
                                        nn.Linear(spread_hidden, n_targets))  # fmt: skip
        self.n_targets = n_targets
        self.n_expert = n_expert
        self.spread_hidden = spread_hidden
        #: the body for inference through oneDNN (set on :meth:`fused` copies)
        self.packed: PackedBody | None = None

    def fused(self, pack: bool = True) -> LineCNN:
        """An inference copy with each batch norm folded into its convolution and, with
        ``pack`` where this torch has oneDNN, the body packed for it (:class:`PackedBody`:
        the copy then serves only calls without gradients)."""
        out = copy.deepcopy(self).eval()
        layers, body = list(out.body), []
        i = 0
        while i < len(layers):
            conv = layers[i]
            if isinstance(conv, nn.Conv1d) and isinstance(layers[i + 1], nn.BatchNorm1d):
                bn = layers[i + 1]
                g = bn.weight / torch.sqrt(bn.running_var + bn.eps)
                conv.weight.data = (conv.weight * g[:, None, None]).detach()
                conv.bias.data = ((conv.bias - bn.running_mean) * g + bn.bias).detach()
                i += 1
            body.append(conv)
            i += 1
        out.body = nn.Sequential(*body)
        out.packed = PackedBody.of(out.body) if pack else None
        return out

    def forward(
        self, x: torch.Tensor, cond: torch.Tensor, expert: torch.Tensor | None = None
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Mean and log-variance (B, n_targets) in standardised units."""
        mean, log_var, _ = self.parts(x, cond, expert)
        return mean, log_var

    @property
    def n_features(self) -> int:
        """Width of :meth:`features`: what the head reads for each line."""
        return self.head[0].in_features

    def features(self, x: torch.Tensor, cond: torch.Tensor,
                 expert: torch.Tensor | None = None) -> torch.Tensor:  # fmt: skip
        """What the head reads (B, :attr:`n_features`): the CNN's mean- and max-pooled
        channels, the conditioning and the expert inputs."""
        if self.packed is not None and not torch.is_grad_enabled():
            h = self.packed(x)
        else:
            h = self.body(x)
        parts = [h.mean(-1), h.amax(-1), cond]
        if self.n_expert:
            if expert is None:
                raise ValueError("this network reads expert inputs: pass expert=")
            parts.append(expert)
        return torch.cat(parts, dim=1)

    def parts(
        self, x: torch.Tensor, cond: torch.Tensor, expert: torch.Tensor | None = None
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Mean, log-variance and the CNN's own (ungated) mean: training fits the own mean
        too, so that it stays an estimate of the targets rather than a correction that
        only makes sense mixed with the expert's."""
        return self.heads(self.features(x, cond, expert), expert)

    def heads(self, features: torch.Tensor, expert: torch.Tensor | None = None
              ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:  # fmt: skip
        """:meth:`parts` from the head's inputs (:meth:`features`)."""
        out = self.head(features)
        t = self.n_targets
        own = out[:, :t]
        if self.spread is None:
            log_var, gate_rows = out[:, t : 2 * t], out[:, 2 * t :]
        else:
            log_var, gate_rows = self.spread(features), out[:, t:]
        mean = own
        if self.n_expert:
            # the expert estimates the last targets (U0', K', eta), not the friction
            e = torch.cat([own[:, : t - 3], expert[:, :3]], dim=1)
            mean = own + torch.sigmoid(gate_rows) * (e - own)
        return mean, log_var.clamp(-12.0, 6.0), own


def expert_inputs(expert: TrainedModel, X: torch.Tensor, spec: LineSpec,
                  y_mean: np.ndarray, y_std: np.ndarray) -> torch.Tensor:  # fmt: skip
    """Expert inputs (B, :data:`N_EXPERT`) of stacked lines (:func:`line_inputs`).

    The window model reads the force channel of ``X`` (the line the CNN reads, on the
    reference lattice and pixel); its per-line estimate is the mean over windows (as
    in the paper). Returned: ln U0', ln K' and ln eta of that estimate in the line
    model's standardised target units (clipped to +-5 so that nonsense far outside the
    expert's training range stays bounded), then ln of the windows' standard deviation
    of ln U0' and ln K'.
    """
    est = predict_windows(expert, input_force_nN(X, spec))  # (B, W, targets), physical
    U0 = np.clip(est[..., expert.targets.index("U0_eV")], 1e-3, None)
    K = np.clip(est[..., expert.targets.index("K_N_m")], 1e-2, None)
    lu, lk = np.log(U0.mean(axis=1)), np.log(K.mean(axis=1))
    le = np.log(eta_from(np.exp(lu), np.exp(lk), spec.lattice_nm))
    e = (np.column_stack([lu, lk, le]) - y_mean[-3:]) / y_std[-3:]
    spread = np.log(np.column_stack([np.log(U0).std(axis=1), np.log(K).std(axis=1)]) + 1e-3)
    return torch.from_numpy(np.column_stack([np.clip(e, -5.0, 5.0), spread]).astype(np.float32))


def gaussian_nll(
    mean, log_var, y, beta: float = 0.5, beta_var: float | None = None
) -> torch.Tensor:
    """beta-NLL (Seitzer et al. 2022): NLL weighted by var^beta, so the means of
    hard examples are still learned. Summed over targets, averaged over the batch.

    ``beta_var`` (default ``beta``) weighs the variance's gradient separately. With
    ``beta_var = 0`` every example pulls on its variance equally: under ``beta`` alone,
    precise examples (a pristine line, var ~ 1e-3 in standardised units) weigh ~30x
    less than corrupted ones in the variance fit, and the head leaves their variance
    several times too wide.
    """
    if beta_var is None or beta_var == beta:
        nll = 0.5 * (log_var + (y - mean) ** 2 / log_var.exp())
        if beta:
            nll = nll * log_var.detach().exp() ** beta
        return nll.sum(dim=1).mean()
    var, sq = log_var.exp(), (y - mean) ** 2
    v = var.detach()
    mean_term = 0.5 * sq / v * v**beta  # gradient of beta-NLL in the mean only
    var_term = 0.5 * (log_var + sq.detach() / var) * v**beta_var  # ... in the variance only
    return (mean_term + var_term).sum(dim=1).mean()


#: The contact a user may state (``--contact``): ``"any"``, the calibration prior's
#: contacts (single-point and multi-asperity tips, on substrates three quarters of which
#: are modulated or carry defects, where U0 is the substrate's mean barrier: PHYSICS.md),
#: or ``"ideal"``, one asperity on a crystal without modulation or defects along the
#: line (a sharp tip on a terrace), where the line shows the barrier it is asked for.
ANY_CONTACT = "any"
CONTACTS = (ANY_CONTACT, "ideal")
#: The fields of :class:`LineEnsemble` that a spread calibration fits.
CALIBRATION_STATE = ("scale", "exponent", "shape", "friction_factor", "evidence",
                     "evidence_range", "location", "location_range")  # fmt: skip
#: What the location calibration reads of each line and target, in this order: the
#: line's noise over its own std (:func:`~stickslip.estimators.noise.log_noise_ratio`),
#: ln of the ensemble's raw spread and the ensemble's mean (standardised units).
LOCATION_INPUTS = ("noise", "spread", "estimate")
#: The targets whose mean the location calibration moves: the members read noisy lines
#: stiff and their eta soft. U0's median error on the calibration lines is set mostly by
#: the substrates and contacts of the training prior, which a line does not show, and a
#: shift fitted there moved clean lines' U0 off (docs/explanation/calibration.md,
#: "Where the estimate sits").
LOCATED_TARGETS = ("log_K_ref", "log_eta")


@dataclass
class LineEnsemble:
    """Members, target normalisation and the calibration of their predictive spread.

    The calibrated std of a line is ``scale * sd ** exponent`` (``sd`` the ensemble's
    raw predictive std, standardised units): ``scale`` and ``exponent`` have one entry
    per target (n_targets,) or, with ``classes``, one row per class of line
    (n_classes, n_targets); no ``exponent`` means 1 (a plain scale factor). ``shape``
    (n_targets, len(SHAPE_LEVELS)) holds the quantiles of ``|error| / calibrated std``
    on the calibration lines, from which :meth:`z_at` gives the half-width of an
    interval at any level (a Gaussian's without it). ``location`` moves the members'
    mean before any of this: the median error the calibration lines leave given what a
    line shows (:meth:`location_shift`).
    """

    members: list[LineCNN]
    spec: LineSpec
    y_mean: np.ndarray
    y_std: np.ndarray
    scale: np.ndarray = field(default_factory=lambda: np.ones(len(TARGETS)))
    expert: TrainedModel | None = None
    classes: SpreadClasses | None = None
    exponent: np.ndarray | None = None
    shape: np.ndarray | None = None
    #: offsets one line cannot tell from friction, added to the single-line <F>
    #: interval (:mod:`stickslip.estimators.offsets`); None: no such term
    offset: OffsetPrior | None = None
    #: compressions of large signals (saturation) one line cannot tell from a softer
    #: contact, added to the single-line <F> interval (:class:`~stickslip.estimators.
    #: offsets.CompressionPrior`); None: no such term
    compression: CompressionPrior | None = None
    #: (2, k): levels and the factors on the model's own <F> half-width that the
    #: single-line interval, with the offset and compression terms, takes at them
    #: (:func:`~stickslip.estimators.offsets.fit_friction_factor`); None: 1
    friction_factor: np.ndarray | None = None
    #: (n_targets, 1 + len(EVIDENCE)): the calibrated std's factor ``exp(b0 + b . e)``
    #: on what the line shows (:mod:`stickslip.estimators.evidence`); None: 1
    evidence: np.ndarray | None = None
    #: (2, len(EVIDENCE)): the calibration lines' range of ``e``, to which a line's is
    #: clipped (no extrapolation beyond what the fit saw)
    evidence_range: np.ndarray | None = None
    #: (n_targets, 1 + len(LOCATION_INPUTS)): the median error of the members' mean
    #: (standardised units) on the calibration lines, ``c0 + c . u`` in what a line shows
    #: (:data:`LOCATION_INPUTS`), taken off every mean (:meth:`location_shift`); None: 0
    location: np.ndarray | None = None
    #: (2, n_targets, len(LOCATION_INPUTS)): the calibration lines' range of ``u``, to
    #: which a line's is clipped (no extrapolation beyond what the fit saw)
    location_range: np.ndarray | None = None
    #: calibrations for a contact the user states (:data:`CONTACTS`), each the
    #: :data:`CALIBRATION_STATE` fields fitted on the calibration lines of such contacts
    #: only; the fields above are the calibration for any contact
    contact_calibrations: dict[str, dict[str, np.ndarray | None]] = field(
        default_factory=dict)

    def calibration_state(self) -> dict[str, np.ndarray | None]:
        """Copies of the fields a spread calibration fits (:data:`CALIBRATION_STATE`)."""
        return {k: None if getattr(self, k) is None else np.array(getattr(self, k), float)
                for k in CALIBRATION_STATE}  # fmt: skip

    def for_contact(self, contact: str) -> LineEnsemble:
        """This ensemble calibrated for the stated ``contact`` (:data:`CONTACTS`): itself
        for ``"any"``, else a copy sharing the members with that contact's calibration.

        Raises
        ------
        ValueError
            For a contact this model holds no calibration of.
        """
        if contact == ANY_CONTACT:
            return self
        if contact not in self.contact_calibrations:
            held = ", ".join([ANY_CONTACT, *sorted(self.contact_calibrations)])
            raise ValueError(f"this model holds no calibration for the contact '{contact}' "
                             f"(it holds: {held})")  # fmt: skip
        return replace(self, **self.contact_calibrations[contact])

    def evidence_factor(self, e: np.ndarray) -> np.ndarray:
        """The factor on the calibrated std of lines with evidence ``e`` (B, len(EVIDENCE)),
        (B, n_targets) (1 without an evidence calibration)."""
        if self.evidence is None:
            return np.ones((e.shape[0], len(TARGETS)))
        if self.evidence_range is not None:
            e = np.clip(e, self.evidence_range[0], self.evidence_range[1])
        b = np.asarray(self.evidence, float)
        return np.exp(b[:, 0][None, :] + e @ b[:, 1:].T)

    @staticmethod
    def location_inputs(noise: np.ndarray, mean: np.ndarray, sd: np.ndarray) -> np.ndarray:
        """What the location calibration reads (:data:`LOCATION_INPUTS`), (B, n_targets,
        3), from the lines' noise coordinate (B,) and the members' standardised mean and
        raw spread (B, n_targets)."""
        mean = np.asarray(mean, float)
        noise = np.broadcast_to(np.asarray(noise, float)[:, None], mean.shape)
        return np.stack([noise, np.log(np.asarray(sd, float)), mean], axis=-1)

    def location_shift(self, noise: np.ndarray, mean: np.ndarray, sd: np.ndarray
                       ) -> np.ndarray:  # fmt: skip
        """What :attr:`location` takes off the members' standardised mean of lines with
        noise coordinate ``noise`` (B,), mean and raw spread ``sd`` (B, n_targets); zeros
        without a location calibration."""
        mean = np.asarray(mean, float)
        if self.location is None:
            return np.zeros_like(mean)
        u = self.location_inputs(noise, mean, sd)
        if self.location_range is not None:
            u = np.clip(u, self.location_range[0], self.location_range[1])
        c = np.asarray(self.location, float)
        return c[:, 0][None, :] + np.einsum("btk,tk->bt", u, c[:, 1:])

    def z_at(self, level: float) -> np.ndarray:
        """Half-width of the central interval at ``level`` in calibrated stds, per target
        (n_targets,): interpolated in ``shape``, or the Gaussian quantile without it."""
        if self.shape is None:
            return np.full(len(TARGETS), gaussian_z(level))
        return np.array([np.interp(level, SHAPE_LEVELS, q) for q in self.shape])

    def friction_z_at(self, level: float) -> float:
        """Half-width at ``level``, in calibrated stds, of the model's own <F> error as
        the single-line interval adds it to the offset and compression terms: ``z_at``
        times the fitted :attr:`friction_factor` (interpolated between its levels)."""
        z = float(self.z_at(level)[0])
        if self.friction_factor is None:
            return z
        levels, factors = np.asarray(self.friction_factor, float)
        return z * float(np.interp(level, levels, factors))

    def line_classes(self, X: torch.Tensor, C: torch.Tensor) -> np.ndarray:
        """Spread class of each input line (:class:`SpreadClasses`; all 0 without)."""
        if self.classes is None:
            return np.zeros(X.shape[0], int)
        ratio = C[:, 0].numpy().astype(float) + 1.0
        return self.classes.classify(input_force_nN(X, self.spec), ratio)

    def expert_for(self, X: torch.Tensor) -> torch.Tensor | None:
        """The members' expert inputs for ``X`` (None for a model without an expert)."""
        if self.expert is None:
            return None
        return expert_inputs(self.expert, X, self.spec, self.y_mean, self.y_std)

    def fused_members(self) -> list[LineCNN]:
        """Inference copies of the members (:meth:`LineCNN.fused`), to pass to several
        :meth:`predict_std` calls on the same members."""
        return [m.fused() for m in self.members]

    @torch.inference_mode()
    def predict_std(self, X: torch.Tensor, C: torch.Tensor, features: np.ndarray | None = None,
                    fused: list[LineCNN] | None = None, evidence: np.ndarray | None = None
                    ) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
        """Predictive mean and calibrated std in standardised target units (B, n_targets);
        the central interval at level ``q`` is ``mean +- z_at(q) * std``.

        ``features``: an array (members, B, :attr:`LineCNN.n_features`) to fill with what
        each member's head read for each line (the domain verdict's embedding), at no
        extra cost. ``fused``: the members' :meth:`fused_members` (made here without).
        ``evidence``: the lines' evidence (:func:`~stickslip.estimators.evidence.
        line_evidence`), where already read.
        """
        # batch norm folded, and chunks small enough for the activations to stay in
        # cache: about 5x faster on a CPU than one big batch
        if fused is None:
            fused = self.fused_members()
        E = self.expert_for(X)
        means = np.empty((len(fused), X.shape[0], len(TARGETS)), np.float32)
        variances = np.empty_like(means)
        for k, m in enumerate(fused):
            for i in range(0, X.shape[0], INFER_CHUNK):
                sl = slice(i, i + INFER_CHUNK)
                e = None if E is None else E[sl]
                f = m.features(X[sl], C[sl], e)
                if features is not None:
                    features[k, sl] = f.numpy()
                mu, lv, _ = m.heads(f, e)
                means[k, sl] = mu.numpy()
                variances[k, sl] = lv.exp().numpy()
        mean = means.mean(axis=0)
        sd = np.sqrt(np.mean(variances, axis=0) + means.var(axis=0))
        scale = np.asarray(self.scale)
        exponent = np.ones_like(scale) if self.exponent is None else np.asarray(self.exponent)
        if self.location is not None:
            noise = log_noise_ratio(input_force_nN(X, self.spec))
            mean = mean - self.location_shift(noise, mean, sd)
        if scale.ndim == 2:
            cls = self.line_classes(X, C)
            scale, exponent = scale[cls], exponent[cls]
        if self.evidence is not None and evidence is None:
            evidence = line_evidence_batch(input_force_nN(X, self.spec),
                                           self.spec.lattice_nm / self.spec.pixel_nm)  # fmt: skip
        factor = 1.0 if self.evidence is None else self.evidence_factor(evidence)
        return mean, scale * sd**exponent * factor

    def predict(self, X: torch.Tensor, C: torch.Tensor) -> tuple[np.ndarray, np.ndarray]:
        """Predictive mean and std in target units (``TARGETS``: F, ln U0', ln K', ln eta)."""
        mu, sd = self.predict_std(X, C)
        return mu * self.y_std + self.y_mean, sd * self.y_std


@dataclass
class LinePrediction:
    """Estimates for N traces with uncertainty (arrays of length N).

    ``values[name]`` is the predictive mean (median for the log-normal U0, K, eta),
    ``std[name]`` its standard deviation (that of the Gaussian, or log-normal, with the
    same 68 % interval: the errors' tails are heavier than a Gaussian's), ``lo68/hi68``
    and ``lo95/hi95`` the central 68 % and 95 % intervals, for name in
    ``F_mean_nN, U0_eV, K_N_m, eta``.
    """

    values: dict[str, np.ndarray]
    std: dict[str, np.ndarray]
    lo68: dict[str, np.ndarray]
    hi68: dict[str, np.ndarray]
    lo95: dict[str, np.ndarray]
    hi95: dict[str, np.ndarray]
    #: std of the model's own <F> error, without the offset and compression terms (what
    #: a trace/retrace pair, which cancels the offset, is given)
    F_model_std: np.ndarray | None = None
    #: what each member's head read for each line, (members, N, D), when asked for
    features: np.ndarray | None = None
    #: what each mapped line shows of visible effects, (N, len(EVIDENCE))
    #: (:func:`~stickslip.estimators.evidence.line_evidence`)
    evidence: np.ndarray | None = None
    #: what each mapped line shows of a local anomaly (a defect), (N,)
    #: (:func:`~stickslip.estimators.evidence.local_evidence`; not read by the calibration)
    local_evidence: np.ndarray | None = None


def predict_std_lines(ens: LineEnsemble, lines: list[np.ndarray], cond: torch.Tensor,
                      batch: int = 2048, features: np.ndarray | None = None,
                      evidence: np.ndarray | None = None
                      ) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """Standardised predictive mean and std (N, n_targets) of mapped lines, each read
    whole: lines of equal length are batched together. ``features``: an array (members,
    N, D) to fill with the head's inputs (:meth:`LineEnsemble.predict_std`);
    ``evidence``: the lines' evidence (N, k), where already read."""
    n = len(lines)
    mu = np.empty((n, len(TARGETS)))
    sd = np.empty((n, len(TARGETS)))
    sizes = np.array([f.size for f in lines])
    fused = ens.fused_members()
    for size in np.unique(sizes):
        idx = np.flatnonzero(sizes == size)
        for start in range(0, idx.size, batch):
            sel = idx[start : start + batch]
            X = line_inputs([lines[i] for i in sel], ens.spec)
            part = None if features is None else np.empty(
                (features.shape[0], sel.size, features.shape[2]), features.dtype)  # fmt: skip
            e = None if evidence is None else evidence[sel]
            mu[sel], sd[sel] = ens.predict_std(X, cond[sel], part, fused, e)
            if features is not None:
                features[:, sel] = part
    return mu, sd


def predict_lines(
    ens: LineEnsemble,
    lines: list[np.ndarray],
    lattice_nm: np.ndarray,
    velocity_nm_per_s: np.ndarray,
    trace_mean_nN: np.ndarray,
    batch: int = 2048,
    features: bool = False,
    trace_m3_nN: np.ndarray | None = None,
    temperature_K: np.ndarray | None = None,
) -> LinePrediction:
    """Predict from mapped lines (see :func:`map_line`) with their lattice and velocity
    (and temperature, read by models that condition on it; None: the model's).

    ``trace_mean_nN`` is each trace's own mean force (on its original samples), to which
    the predicted friction correction is added. Lines of equal length are batched
    together; each is read whole (no crop). With ``features``, the prediction also
    carries what each member's head read (:attr:`LinePrediction.features`).
    ``trace_m3_nN``: each trace's :func:`~stickslip.estimators.offsets.compression_moment`
    (on its original samples), which sizes the model's compression term (None: 0).
    """
    n = len(lines)
    a = np.broadcast_to(np.asarray(lattice_nm, float), (n,))
    v = np.broadcast_to(np.asarray(velocity_nm_per_s, float), (n,))
    feats = np.empty((len(ens.members), n, ens.members[0].n_features), np.float32) \
        if features else None
    cond = conditioning(a, v, ens.spec, temperature_K)
    # read once: the calibration's width factor and the rows' evidence columns
    evidence = line_evidence(lines, ens.spec.lattice_nm / ens.spec.pixel_nm)
    mu, sd = predict_std_lines(ens, lines, cond, batch, feats, evidence)
    mu, sd = mu * ens.y_std + ens.y_mean, sd * ens.y_std
    s = a / ens.spec.lattice_nm
    shift = {"F_mean_nN": 0.0, "U0_eV": np.log(s), "K_N_m": -np.log(s), "eta": 0.0}
    z68, z95 = ens.z_at(0.68), ens.z_at(0.95)
    out = LinePrediction({}, {}, {}, {}, {}, {}, features=feats, evidence=evidence,
                         local_evidence=local_evidence(lines, ens.spec.lattice_nm
                                                       / ens.spec.pixel_nm))  # fmt: skip
    for j, name in enumerate(("F_mean_nN", "U0_eV", "K_N_m", "eta")):
        m, h68, h95 = mu[:, j], z68[j] * sd[:, j], z95[j] * sd[:, j]
        e = h68 / Z68  # std of the Gaussian with this 68 % interval
        if name == "F_mean_nN":
            m = m + np.asarray(trace_mean_nN, float)
            out.F_model_std = e
            m3 = 0.0 if trace_m3_nN is None else np.asarray(trace_m3_nN, float)
            t68, t95 = (ens.friction_z_at(q) * sd[:, j] for q in (0.68, 0.95))
            lo68, hi68 = friction_bounds(t68, 0.68, ens.offset, ens.compression, m3)
            lo95, hi95 = friction_bounds(t95, 0.95, ens.offset, ens.compression, m3)
            out.values[name], out.std[name] = m, (hi68 - lo68) / (2.0 * Z68)
            out.lo68[name], out.hi68[name] = m + lo68, m + hi68
            out.lo95[name], out.hi95[name] = m + lo95, m + hi95
            continue
        m = m + shift[name]
        out.values[name] = np.exp(m)
        out.std[name] = lognormal_std(np.exp(m), e)
        out.lo68[name], out.hi68[name] = np.exp(m - h68), np.exp(m + h68)
        out.lo95[name], out.hi95[name] = np.exp(m - h95), np.exp(m + h95)
    return out


def predict_raw_lines(
    ens: LineEnsemble,
    x_nm: list[np.ndarray],
    force_nN: list[np.ndarray],
    lattice_nm: np.ndarray,
    velocity_nm_per_s: np.ndarray,
    features: bool = False,
    temperature_K: np.ndarray | None = None,
) -> LinePrediction:
    """Map traces of any pixel size and lattice (see :func:`map_line`), then predict
    (:func:`predict_lines`; ``features``: also what the members' heads read).

    Raises
    ------
    ValueError
        If a mapped trace has fewer than ``spec.min_pixels`` pixels.
    """
    n = len(force_nN)
    a = np.broadcast_to(np.asarray(lattice_nm, float), (n,))
    lines: list[np.ndarray] = [np.empty(0)] * n
    means = np.empty(n)
    m3 = np.empty(n) if ens.compression is not None else None  # only its term reads it
    for idx in line_groups(x_nm, a):
        F = np.stack([np.asarray(force_nN[i], float) for i in idx])
        mapped = to_reference(x_nm[idx[0]], F, a[idx[0]], ens.spec.reference)
        for k, i in enumerate(idx):
            lines[i] = mapped[k]
        means[idx] = F.mean(axis=1)
        if m3 is not None:
            m3[idx] = compression_moment(F)
    short = [i for i, f in enumerate(lines) if f.size < ens.spec.min_pixels]
    if short:
        raise ValueError(f"traces {short} are shorter than {ens.spec.min_pixels} mapped pixels")
    return predict_lines(ens, lines, a, velocity_nm_per_s, means, features=features,
                         trace_m3_nN=m3, temperature_K=temperature_K)  # fmt: skip
