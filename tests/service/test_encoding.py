"""Content-coding negotiation of large GLB bodies (Accept-Encoding, RFC 9110 12.5.3) and its encoders."""

from __future__ import annotations

import gzip

import pytest
import zstandard

from pdeanim_service.api.encoding import accepted_coding, encode


@pytest.mark.parametrize("header, expected", [
    ("", None), ("identity", None), ("gzip, deflate", "gzip"), ("gzip, deflate, br, zstd", "zstd"),
    ("GZIP;Q=0.5, ZSTD;q=0.1", "zstd"), ("zstd;q=0, gzip", "gzip"), ("zstd;q=0, gzip;q=0", None),
    ("*", "zstd"), ("*;q=0", None), ("zstd;q=0, *", "gzip"), ("gzip;q=bad", None), (" , gzip ,", "gzip"),
    ("br", None), ("deflate, gzip;q=0.001", "gzip"),
])
def test_accepted_coding(header, expected):
    assert accepted_coding(header) == expected


def test_encodings_round_trip():
    body = bytes(range(256)) * 4000
    assert gzip.decompress(encode(body, "gzip")) == body
    assert zstandard.ZstdDecompressor().decompress(encode(body, "zstd")) == body
    with pytest.raises(ValueError, match="unknown content coding"):
        encode(body, "br")
