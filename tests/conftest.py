"""Shared pytest configuration: paths to the golden vectors and the shipped robots."""

from __future__ import annotations

from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="session")
def firmware_protocol_dir() -> Path:
    """The single source of truth for bytes on the wire (golden vectors, .msg, DBC)."""
    return REPO / "firmware_protocol"
