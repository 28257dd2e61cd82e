"""The one place hdjax sets up matplotlib (an optional dependency, imported on first use).

matplotlib is imported lazily, inside [`pyplot`][], so that `import hdjax` stays light and works
without it; every figure of the package goes through this helper, which selects the
non-interactive Agg backend (figures are written to files, never shown).
"""

from __future__ import annotations

import io

from ._errors import ConfigError


def pyplot():
    """`matplotlib.pyplot` with the Agg backend; `ConfigError` saying how to install it if
    matplotlib is missing."""
    try:
        import matplotlib  # optional dependency: imported on first use (see module docstring)
    except ImportError as err:  # pragma: no cover - depends on the environment
        raise ConfigError(
            f"figures need matplotlib ({err}); install it (pip install matplotlib) or turn "
            "figures off"
        ) from err
    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    return plt


def fixed_margins(
    fig, *, left=0.8, right=0.2, bottom=0.55, top=0.35, hspace=0.55, wspace=0.3
) -> None:
    """Margins in inches (axis labels and a title fit), instead of `tight_layout`.

    `tight_layout` measures every text by drawing the figure, and leaves a layout engine that
    makes `savefig` draw it once more: three draws per figure, most of a report's figure time.
    """
    w, h = fig.get_size_inches()
    fig.subplots_adjust(
        left=left / w, right=1 - right / w, bottom=bottom / h, top=1 - top / h,
        hspace=hspace, wspace=wspace,
    )  # fmt: skip


def save_figure(fig, path, *, dpi: int = 110) -> None:
    """Write `fig` to `path` and close it."""
    fig.savefig(path, dpi=dpi)
    pyplot().close(fig)


def png_bytes(fig, *, dpi: int = 110) -> bytes:
    """`fig` as PNG bytes (for an atomic write into a result folder), and close it."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    pyplot().close(fig)
    return buf.getvalue()
