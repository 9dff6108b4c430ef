"""The base model and every candidate of a diagnosis as one model, so that one
compiled kernel fits them all.

The candidate extensions are nested around the base in [`jaxcable.EXTENSIONS`][]'s
order (creep changes innermost, then temperature, then the apparatus), each at the
null value of its effect (`switched_off`, the base exactly) except the one being
fitted, which starts from its `wrap` values. A fit is then which parameters are free
(`jaxcable._fit.fit_subset`): the base's, plus the candidate's effect fields. The
results are given back as the base's or the candidate's own model and names
(`Stack.result_of`), as if each had been fitted alone: at the null values the other
layers change nothing.
"""

import dataclasses
import warnings

import equinox as eqx

from .._fit import (
    FitResult,
    IdentifiabilityWarning,
    field_at,
    fit_subset,
    shared_layout,
)
from .._models import EXTENSIONS, AbstractCableModel


@dataclasses.dataclass(frozen=True)
class Stack:
    """The extensions `ids` nested around a base model, innermost first.

    **Fields:**

    - `ids`: the candidate ids in the stack (those that can wrap the base).
    - `base_names`: the base's fitted parameters (its own paths).
    """

    ids: tuple[str, ...]
    base_names: tuple[str, ...]

    @property
    def base_prefix(self) -> str:
        return "base." * len(self.ids)

    def _prefix(self, ext_id: str) -> str:
        """The path of the layer `ext_id` in the stack, with a trailing dot ('' for
        the outermost)."""
        return "base." * (len(self.ids) - 1 - self.ids.index(ext_id))

    def model(self, base: AbstractCableModel, active: str | None) -> AbstractCableModel:
        """The stack around `base`: every layer off but `active` (None: all off;
        `"all"`: every layer at its start values, for the layout)."""
        m = base
        for ext_id in self.ids:
            cls = EXTENSIONS[ext_id]
            on = active in (ext_id, "all")
            m = cls.wrap(m) if on else cls.switched_off(m)
        return m

    def free(self, active: str | None) -> tuple[str, ...]:
        """The stack's paths of the parameters a fit of `active` frees."""
        names = tuple(self.base_prefix + n for n in self.base_names)
        if active is None:
            return names
        own = EXTENSIONS[active].EFFECT_FIELDS
        return names + tuple(self._prefix(active) + f for f in own)

    @property
    def size(self) -> int:
        """The most parameters any fit frees: the solver's vector length."""
        return len(self.base_names) + max(
            (len(EXTENSIONS[i].EFFECT_FIELDS) for i in self.ids), default=0
        )

    def layout(self, base: AbstractCableModel, tests, drive):
        """The layout of every parameter any fit frees."""
        union = tuple(dict.fromkeys(n for i in (None, *self.ids) for n in self.free(i)))
        return shared_layout(self.model(base, "all"), tests, union, drive=drive)

    def fit_stacked(self, start, tests, layout, active, **kwargs) -> FitResult:
        """Fit `start` (a stack) with the parameters of `active` free: the result
        with the stack's model and paths."""
        return fit_subset(
            start, tests, layout, self.free(active), size=self.size, **kwargs
        )

    def fit(self, start, tests, layout, active, **kwargs) -> FitResult:
        """`fit_stacked`, the result as the base's or the candidate's own (see
        `result_of`)."""
        stacked = self.fit_stacked(start, tests, layout, active, **kwargs)
        return self.result_of(stacked, active)

    def own_model(self, stack: AbstractCableModel, active: str | None):
        """The base model (`active` None) or the candidate's extension around it,
        with the values of `stack`."""
        base = field_at(stack, self.base_prefix[:-1]) if self.ids else stack
        if active is None:
            return base
        layer = (
            field_at(stack, self._prefix(active)[:-1])
            if self._prefix(active)
            else stack
        )
        return eqx.tree_at(lambda m: m.base, layer, base)

    def result_of(self, result: FitResult, active: str | None) -> FitResult:
        """`result` of a stack fit with the model, per-test models and names of the
        base (`active` None) or of `active` around it (`base.NAME` and its fields)."""
        prefix = self.base_prefix
        outer = "" if active is None else self._prefix(active)

        def own(name: str) -> str:
            if name.startswith(prefix):
                return ("" if active is None else "base.") + name[len(prefix) :]
            return name[len(outer) :]

        return dataclasses.replace(
            result,
            model=self.own_model(result.model, active),
            models=tuple(self.own_model(m, active) for m in result.models),
            names=tuple(own(n) for n in result.names),
        )


def stack_of(base: AbstractCableModel, ids, base_names) -> Stack:
    """The [`Stack`][] of the candidates `ids` that can wrap `base` (`wrap` raises
    for the others, e.g. `hereditary` around a model without Park's creep)."""
    usable = []
    m = base
    for ext_id in ids:
        try:
            m = EXTENSIONS[ext_id].switched_off(m)
        except ValueError:
            continue
        usable.append(ext_id)
    return Stack(tuple(usable), tuple(base_names))


def stack_fitter(stack: Stack, how, base_model, **options):
    """`fitter(active, multistart=1)`: the `fitter` of `_score` for the base (`active`
    None) or a candidate, every one through the stack's one compiled kernel (a layout per
    number of training tests)."""
    layouts: dict[int, object] = {}

    def layout(tests, drives):
        if len(tests) not in layouts:
            layouts[len(tests)] = stack.layout(base_model, tests, drives)
        return layouts[len(tests)]

    def fitter(active, multistart=1):
        def run(start, tests, index):
            drives = [how.drive_names[i] for i in index]
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", IdentifiabilityWarning)
                raw = stack.fit_stacked(
                    start,
                    tests,
                    layout(tests, drives),
                    active,
                    throw=False,
                    drive=drives,
                    covariate=how.covariate,
                    multistart=multistart,
                    **options,
                )
            return stack.result_of(raw, active), raw.model

        return run

    return fitter
