"""Several outputs read from one signal: an affine or cubic map per output, or one output of such a block."""

from __future__ import annotations

import casadi as ca
import numpy as np

from ._block import AbstractBlock, Parameter
from ._errors import PhysicsError
from ._traits import BlockTraits


class OutputMaps(AbstractBlock):
    """``y_j = gain_j * u + offset_j`` for ``j = 1..outputs`` (``cubic=True``: plus ``c2_j d^2 + c3_j d^3``,
    ``d = u - center``); memoryless.

    The last block of a model with several outputs (the tip's angle and its position, say) that
    one chain of blocks drives: the chain keeps one internal state, and each output reads the
    chain's signal through its own map. With one output it is :class:`~physics.LinearMap`, whose
    parameter names a single-output model keeps.

    Parameters
    ----------
    outputs : int, default 2
        The number of outputs.
    cubic : bool, default False
        Each output also bends with its own quadratic and cubic terms about ``center`` (input units; the
        middle of the fitted signal's range, set by identification): the static nonlinearity of
        :class:`~physics.Poly`, one per output.
    center : float, default 0
        Where the cubic terms are centred.
    **values : float
        ``gain_1``, ``offset_1`` (``c2_1``, ``c3_1``), ``gain_2``, ... (defaults 1 and 0).

    Examples
    --------
    >>> import numpy as np
    >>> from physics import Series, Lag, OutputMaps
    >>> model = Series(Lag(time_constant_s=0.1), OutputMaps(outputs=2, gain_2=-2.0, offset_2=5.0))
    >>> model.n_y, model.simulate(np.ones(3)).shape
    (2, (3, 2))
    """

    name = "maps"
    rank = 5

    def __init__(self, outputs: int = 2, cubic: bool = False, center: float = 0.0, **values: float):
        if isinstance(outputs, bool) or int(outputs) != outputs or outputs < 2:
            raise PhysicsError(f"OutputMaps needs a whole number of outputs >= 2 (one output: LinearMap). "
                               f"Got {outputs!r} instead.")
        if not np.isfinite(center):
            raise PhysicsError(f"OutputMaps' center must be a finite number (input units). Got {center!r} instead.")
        self.outputs, self.cubic, self.center = int(outputs), bool(cubic), float(center)
        pars = []
        for j in range(1, self.outputs + 1):
            pars += [Parameter(f"gain_{j}", 1.0, -1e9, 1e9, "output unit / input unit", f"slope of output {j}",
                               scaling=(-1, 1)),
                     Parameter(f"offset_{j}", 0.0, -1e9, 1e9, "output unit", f"output {j} at zero input",
                               scaling=(0, 1))]
            if self.cubic:
                pars += [Parameter(f"c2_{j}", 0.0, -1e9, 1e9, "output unit / input unit^2",
                                   f"quadratic term of output {j}", scaling=(-2, 1)),
                         Parameter(f"c3_{j}", 0.0, -1e9, 1e9, "output unit / input unit^3",
                                   f"cubic term of output {j}", scaling=(-3, 1))]
        self.traits = BlockTraits.of(type(self), parameters=tuple(pars))
        self._init_parameters(dict(values))

    @property
    def output_size(self) -> int:
        return self.outputs

    def output_scale(self, s_in, s_y):
        return s_y

    def features(self, u):
        """The terms each output weighs, in its parameters' order: ``u, 1`` (and ``d^2, d^3``)."""
        d = u - self.center
        return (u, 1.0, d * d, d * d * d) if self.cubic else (u, 1.0)

    def output_guess(self, index: int, y, p):
        """The input whose affine part gives output ``index`` the value ``y``: an inverse's start."""
        k = len(self.features(0.0))
        return (y - p[k * index + 1]) / p[k * index]

    def step(self, x, u, p, dt):
        terms = self.features(u)
        k = len(terms)
        return ca.DM.zeros(0, 1), ca.vertcat(*(sum(p[k * j + i] * t for i, t in enumerate(terms))
                                               for j in range(self.outputs)))


class OutputOf(AbstractBlock):
    """One output of a block that outputs several (:class:`OutputMaps`, :class:`~physics.Arc`): the block as a
    path of one output sees it (:meth:`Series.output_view`). Its parameters, states and name are the
    wrapped block's, so the view's parameter names are the model's; its inverse is the Newton root solve
    of :meth:`AbstractBlock.inverse_output` on that output."""

    def __init__(self, block: AbstractBlock, index: int):
        if not isinstance(block, AbstractBlock) or block.output_size < 2:
            raise PhysicsError(f"OutputOf takes a block with several outputs; got {block!r}.")
        if isinstance(index, bool) or int(index) != index or not 0 <= index < block.output_size:
            raise PhysicsError(f"The output index must be in 0..{block.output_size - 1} for '{block.name}'. "
                               f"Got {index!r} instead.")
        self.block, self.index, self.name = block, int(index), block.name
        self.traits = BlockTraits.of(type(self), parameters=block.parameters, smooth_in_input=block.smooth_in_input)
        self._init_parameters(dict(zip([p.name for p in block.parameters], block.param_values())))

    @property
    def state_names(self):
        return self.block.state_names

    def get_settings(self):
        return {"block": self.block.name, "settings": self.block.get_settings(), "index": self.index}

    def step(self, x, u, p, dt):
        x_next, y = self.block.step(x, u, p, dt)
        return x_next, y[self.index]

    def steady_state(self, u0, p):
        return self.block.steady_state(u0, p)

    def inverse_guess(self, x, y, p):
        """Newton's start: the wrapped block's guess for this output (``output_guess``), else ``y``."""
        guess = getattr(self.block, "output_guess", None)
        return y if guess is None else guess(self.index, y, p)
