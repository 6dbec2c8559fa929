"""Moved public names answer at their old path for one release, with a DeprecationWarning
that names the new path (warptissue._deprecated)."""

from __future__ import annotations

import importlib
import subprocess
import sys

import pytest

from warptissue._deprecated import MOVED, REMOVED_IN, moved_attribute


def _resolve(path: str):
    module, _, name = path.rpartition(".")
    return getattr(importlib.import_module(module), name)


@pytest.mark.parametrize(("old", "new"), sorted(MOVED.items()))
def test_an_old_path_warns_naming_the_new_one_and_gives_the_same_object(old, new):
    module, _, name = old.rpartition(".")
    old_module = importlib.import_module(module)
    with pytest.warns(DeprecationWarning) as caught:
        value = getattr(old_module, name)
    assert value is _resolve(new)
    message = str(caught[0].message)
    assert new in message and old in message and REMOVED_IN in message
    assert name not in getattr(old_module, "__all__", ())  # not advertised at the old path


def test_the_user_script_of_the_issue_imports_again_with_the_warning(tmp_path):
    """``from warptissue.study import start_values_from_record`` (an ImportError after the
    move), in a fresh process: the same object, and a DeprecationWarning naming the new path."""
    script = (
        "import warnings\n"
        "with warnings.catch_warnings(record=True) as caught:\n"
        "    warnings.simplefilter('always')\n"
        "    from warptissue.study import start_values_from_record\n"
        "from warptissue.fit.start import start_values_from_record as new\n"
        "assert start_values_from_record is new\n"
        "kinds = {w.category.__name__ for w in caught}\n"
        "texts = [str(w.message) for w in caught]\n"
        "print(kinds, any('warptissue.fit.start.start_values_from_record' in t for t in texts))\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", script],
        capture_output=True,
        text=True,
        timeout=300,
        check=True,
        cwd=tmp_path,  # outside the checkout, whose warptissue/ has no kernels/
    )
    assert done.stdout.strip() == "{'DeprecationWarning'} True"


def test_a_name_that_did_not_move_is_an_attribute_error():
    import warptissue.study

    with pytest.raises(AttributeError, match="no attribute 'no_such_name'"):
        warptissue.study.no_such_name  # noqa: B018
    with pytest.raises(ImportError):
        from warptissue.study import no_such_name  # noqa: F401
    with pytest.raises(AttributeError):
        moved_attribute("warptissue.study", "load_study")  # still there: not a moved name
