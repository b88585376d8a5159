"""Which columns of the measured runs a model folder reads: :class:`Columns`."""

from __future__ import annotations

from dataclasses import dataclass

from physics.data import DataError

__all__ = ["Columns"]


@dataclass(frozen=True)
class Columns:
    """The runs' columns a model folder (:func:`~hybrid.experiments.fit_model_dir`) is fitted on.

    ``time``, ``input`` and ``output`` name the CSV columns the runs were read from: they are kept in
    the folder's manifest so ``hyst predict`` reads new files with them unasked (None: runs not read
    from files, nothing kept). ``measured`` names the runs' ``Trajectory.extra`` columns (e.g. a motor
    current) the residual network reads beside the command and the physics' output; every run, train
    and test, must carry them, and the exported step's input is then ``[u, *measured]``. The runs'
    other extra columns (a simulator's states) are not inputs and are not read. As ``hyst fit
    --input u,current``: the command's column, then the measured inputs.

    ``output`` may name several columns (a tuple, e.g. the tip's ``("Angle x", "Pos x", "Pos y")``: the runs'
    ``y`` by its ``output_name`` and ``Trajectory.extra`` columns): the folder then models them all at once
    (:attr:`outputs`), as ``hyst fit --output "Angle x,Pos x,Pos y"``.

    Examples
    --------
    >>> from hybrid.experiments import Columns
    >>> Columns("t", "u", "y", measured=("current",)).manifest()
    {'time': 't', 'input': 'u,current', 'output': 'y'}
    """

    time: str | None = None
    input: str | None = None
    output: str | None = None
    measured: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if isinstance(self.output, (tuple, list)):
            names = tuple(self.output)
            if len(names) < 2 or len(set(names)) != len(names) or not all(isinstance(n, str) and n for n in names):
                raise DataError(f"Several output columns must be at least two distinct names, e.g. ('Angle x', "
                                f"'Pos y'); got {self.output!r}.")
            object.__setattr__(self, "output", names)
        measured = (self.measured,) if isinstance(self.measured, str) else tuple(self.measured)
        if len(set(measured)) != len(measured) or not all(isinstance(m, str) and m for m in measured):
            raise DataError(f"measured_inputs must be distinct column names; got {self.measured!r}.")
        object.__setattr__(self, "measured", measured)
        for name in ("time", "input", *(() if self.outputs else ("output",))):
            value = getattr(self, name)
            if value is not None and not (isinstance(value, str) and value):
                raise DataError(f"The {name} column of Columns must be a column name or None. Got {value!r} instead.")

    @property
    def outputs(self) -> tuple[str, ...]:
        """The output columns of a model of several (``output`` given as a tuple); () for one output."""
        return self.output if isinstance(self.output, tuple) else ()

    def manifest(self) -> dict[str, str] | None:
        """The columns as the folder's manifest keeps them (``input``: the command, then the measured
        inputs, as ``--input`` takes them), or None when the runs were not read from files."""
        named = {"time": self.time, "input": self.input, "output": self.output}
        if all(v is None for v in named.values()):
            return None
        if self.input is not None and self.measured:
            named["input"] = ",".join([self.input, *self.measured])
        if self.outputs:
            named["output"] = ",".join(self.outputs)
        return {k: v for k, v in named.items() if v is not None}
