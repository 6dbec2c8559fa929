import numpy as np

from warptissue.errors import ConvergenceError, InputError, MeshError, WarpTissueError


def test_input_error_message_names_file_line_column_and_value():
    error = InputError("not a number", path="data/run.csv", line=12, column="force_N", value="abc")
    assert str(error) == "data/run.csv:12, column 'force_N': not a number (got 'abc')"
    assert isinstance(error, WarpTissueError) and isinstance(error, ValueError)
    assert error.exit_code == 2


def test_mesh_and_convergence_errors_carry_context():
    assert str(MeshError("inverted", element=7)) == "element 7: inverted"
    partial = {"force_N": [0.0, 1.0]}
    assert ConvergenceError("cutback exhausted", partial_result=partial).partial_result is partial
    assert len({InputError.exit_code, MeshError.exit_code, ConvergenceError.exit_code}) == 3


def test_numpy_scalars_show_as_plain_numbers():
    error = InputError("must be positive", column="force_N", value=np.float64(-1.19))
    assert str(error) == "column 'force_N': must be positive (got -1.19)"
    assert type(error.value) is float
    assert InputError("bad", value=np.int64(3)).value == 3
    assert "array" in str(InputError("bad", value=np.array([1.0, 2.0])))


def test_an_option_is_named_as_an_option():
    error = InputError("must be >= 1", column="growth", value=0.5)
    assert str(error.for_option("--growth")) == "option --growth: must be >= 1 (got 0.5)"
    assert str(error) == "column 'growth': must be >= 1 (got 0.5)"


def test_a_key_is_named_as_a_key_not_a_column():
    """Parameters and study keys are not data columns: the solver's options once read
    "column 'linear_solver': 'superlu' runs on the CPU"."""
    from warptissue.fem import NewtonOptions

    error = InputError("must lie between 0 and 1", key="tolerance", value=np.float64(2.0))
    assert str(error) == "key 'tolerance': must lie between 0 and 1 (got 2.0)"
    assert error.column == "tolerance"  # callers map the name through one attribute
    assert str(error.for_option("--tolerance")).startswith("option --tolerance: ")
    try:
        NewtonOptions(tolerance=2.0)
    except InputError as caught:
        assert "key 'tolerance'" in str(caught) and "column" not in str(caught)
    else:
        raise AssertionError("NewtonOptions accepted a tolerance of 2")
