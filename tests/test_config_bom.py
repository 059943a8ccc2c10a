"""A config file that starts with a byte-order mark (as Windows editors save UTF-8) reads as the same TOML."""

from __future__ import annotations

import pytest

from cosserat_chain.io import read_config


def test_a_byte_order_mark_is_skipped(tmp_path):
    plain, marked = tmp_path / "plain.toml", tmp_path / "marked.toml"
    text = "N = 3\ngamma_phi = 0.15\n"
    plain.write_text(text, encoding="utf-8")
    marked.write_bytes(b"\xef\xbb\xbf" + text.encode("utf-8"))
    assert read_config(marked) == read_config(plain) == {"N": 3, "gamma_phi": 0.15}
    # Not a licence for other encodings: UTF-16 is still refused with its reason.
    other = tmp_path / "utf16.toml"
    other.write_text(text, encoding="utf-16")
    with pytest.raises(ValueError, match="not UTF-8 text"):
        read_config(other)
