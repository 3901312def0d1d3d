"""Formulas written once and compiled to both numpy and GLSL.

Both ends of pibr evaluate the same maths on the CPU (numpy) and in shaders (GLSL): the
wide-angle projection, depth quantization. Writing each formula twice invites the two to
drift apart, so a :class:`Formula` is a list of scalar assignments in a tiny expression
language that is valid Python and, after a few renames, valid GLSL:

* operators ``+ - * /``, comparisons, parentheses, float literals written with a dot;
* functions ``sqrt``, ``abs``, ``floor``, ``max``, ``min``, ``clamp(x, lo, hi)`` and
  ``select(cond, a, b)`` (``cond ? a : b``), ``exp2``, ``log2``;
* named constants passed in ``constants``.

The numpy side evaluates element-wise on arrays (float64); the GLSL side runs in float32.
Tests check the two agree on the same inputs.
"""
from __future__ import annotations

import re

import numpy as np

_NUMPY_FUNCS = {
    "sqrt": np.sqrt, "abs": np.abs, "floor": np.floor, "max": np.maximum, "min": np.minimum,
    "clamp": np.clip, "select": np.where, "exp2": np.exp2, "log2": np.log2,
}
_ALLOWED_NAME = re.compile(r"[A-Za-z_][A-Za-z_0-9]*")

GLSL_PRELUDE = (  # guarded, so several formula modules can be pasted into one shader
    "#ifndef PIBR_PRELUDE\n#define PIBR_PRELUDE\n"
    "float pibr_select(bool c, float a, float b) { return c ? a : b; }\n"
    "#endif\n"
)


class Formula:
    """``name(inputs) -> outputs`` as a sequence of ``(variable, expression)`` steps."""

    def __init__(self, name: str, inputs: tuple, steps: tuple, outputs: tuple, constants: dict | None = None,
                 glsl_constants: dict | None = None):
        self.name, self.inputs, self.steps, self.outputs = name, tuple(inputs), tuple(steps), tuple(outputs)
        self.constants = dict(constants or {})
        # Guards that depend on the precision (float64 here, float32 in shaders) may differ.
        self.glsl_constants = {**self.constants, **(glsl_constants or {})}
        known = set(self.inputs) | set(self.constants)
        for var, expr in self.steps:
            for word in _ALLOWED_NAME.findall(expr):
                if word not in known and word not in _NUMPY_FUNCS:
                    raise ValueError(f"formula {name}: {word!r} used before it is defined in {var} = {expr}")
            known.add(var)
        missing = [o for o in self.outputs if o not in known]
        if missing:
            raise ValueError(f"formula {name}: outputs never assigned: {missing}")
        self._code = [(var, compile(expr, f"<{name}:{var}>", "eval")) for var, expr in self.steps]

    def numpy(self, **values):
        """Evaluate on arrays (broadcast together); returns one array or a tuple per output."""
        env = dict(_NUMPY_FUNCS)
        env.update(self.constants)
        for k in self.inputs:
            env[k] = np.asarray(values[k], dtype=np.float64)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            for var, code in self._code:
                env[var] = eval(code, {"__builtins__": {}}, env)  # our own constant source, never input
        out = tuple(np.asarray(env[o], dtype=np.float64) for o in self.outputs)
        return out[0] if len(out) == 1 else out

    def glsl(self, return_type: str, result: str) -> str:
        """GLSL function ``return_type name(float input, ...)`` returning ``result``, an expression
        over the output names such as ``"vec3(tx, ty, r)"``."""
        params = ", ".join(f"float {i}" for i in self.inputs)
        lines = [f"{return_type} {self.name}({params}) {{"]
        for k, v in self.glsl_constants.items():
            lines.append(f"    const float {k} = {_glsl_float(v)};")
        declared = set(self.inputs)
        for var, expr in self.steps:
            g = expr.replace("select(", "pibr_select(")
            if var in declared:
                lines.append(f"    {var} = {g};")
            else:
                lines.append(f"    float {var} = {g};")
                declared.add(var)
        lines.append(f"    return {result};")
        lines.append("}")
        return "\n".join(lines) + "\n"


def _glsl_float(v: float) -> str:
    s = repr(float(v))
    return s if ("." in s or "e" in s or "inf" in s) else s + ".0"
