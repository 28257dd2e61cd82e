"""The names that build data and models, or save them, left `hdjax.config` for
`hdjax.pipelines` and `hdjax.modelfile`: the old names still work, and warn."""

import subprocess
import sys

import pytest

import hdjax.config
import hdjax.modelfile
import hdjax.pipelines


@pytest.mark.parametrize(
    "name, home",
    [
        ("build_dataset", hdjax.pipelines),
        ("synthetic_recording", hdjax.pipelines),
        ("StreamedDataset", hdjax.pipelines),
        ("preflight", hdjax.pipelines),
        ("save_model", hdjax.modelfile),
        ("load_model", hdjax.modelfile),
        ("SavedModel", hdjax.modelfile),
    ],
)
def test_old_name_warns_and_is_the_new_one(name, home):
    with pytest.warns(DeprecationWarning, match=f"{home.__name__}.{name}"):
        assert getattr(hdjax.config, name) is getattr(home, name)


def test_unknown_name_is_an_attribute_error():
    with pytest.raises(AttributeError, match="no attribute 'build_datasets'"):
        hdjax.config.build_datasets  # noqa: B018


def test_importing_config_loads_no_model_package():
    code = (
        "import sys, hdjax.config; "
        "print(sorted({m.split('.')[1] for m in sys.modules if m.startswith('hdjax.') "
        "and not m.split('.')[1].startswith('_')}))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "['config', 'reference']"
