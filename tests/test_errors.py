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
