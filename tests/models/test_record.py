"""The model record's contact frames (hpcwedge/models/record.py): orthonormal, right-handed,
given tangents orthogonalised, bad tangents named."""
import numpy as np
import pytest

from hpcwedge.models.record import as_float_array, contact_frames


def test_contact_frames_3d():
    n = np.array([[0, 0, 2.0], [1, 1, 0], [0.3, -0.2, 0.9]])
    nn, t = contact_frames(n, 3, 3)
    F = np.concatenate([nn[:, None], t], axis=1)
    np.testing.assert_allclose(F @ F.transpose(0, 2, 1), np.broadcast_to(np.eye(3), F.shape), atol=1e-15)
    np.testing.assert_allclose(np.linalg.det(F), 1.0)
    nn2, t2 = contact_frames(n, 3, 3, tangents=[[1, 0, 5.0], [0, 0, 1], [1, 0, 0]])
    np.testing.assert_allclose(t2[0, 0], [1, 0, 0], atol=1e-15)          # orthogonalised against n
    np.testing.assert_allclose(t2[1, 0], [0, 0, 1], atol=1e-15)
    with pytest.raises(ValueError, match=r"contact.tangents: tangent zero or parallel to the normal at contact node 0"):
        contact_frames(n, 3, 3, tangents=[[0, 0, 1.0], [0, 0, 1], [1, 0, 0]])
    with pytest.raises(ValueError, match=r"contact.tangents: t2 must be n x t1"):
        contact_frames(n[:1], 3, 1, tangents=[[[1, 0, 0], [0, -1, 0]]])


@pytest.mark.parametrize("value,text", [([["2", "1"], ["1", "4"]], "2"), ("2", "2"), ([1.0, b"3"], b"3"),
                                        ([[1.0, 2.0], [3.0, "x"]], "x"), ([[1.0], [2.0, "y"]], "y")])
def test_text_is_not_a_number(value, text):
    """Text in a numeric array ("2" in K, EA = "2") is refused naming the key and the text, as
    mu = "0.5" is (before: converted silently, while mu and E as text were refused)."""
    with pytest.raises(ValueError) as e:
        as_float_array(value, "model.K")
    assert str(e.value) == f"model.K: numbers expected, got text {text!r}"
