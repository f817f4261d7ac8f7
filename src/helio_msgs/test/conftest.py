"""Shared helpers for the helio_msgs plumbing tests."""

import importlib
import pathlib

import pytest

INTERFACE_DIR = pathlib.Path(__file__).resolve().parent.parent


def interface_names():
    """Every (kind, name) declared in this package's msg/, srv/ and action/ folders."""
    names = []
    for kind, suffix in (('msg', '.msg'), ('srv', '.srv'), ('action', '.action')):
        for path in sorted((INTERFACE_DIR / kind).glob('*' + suffix)):
            names.append((kind, path.stem))
    return names


def load_interface(kind, name):
    """Import helio_msgs.<kind>.<name>."""
    return getattr(importlib.import_module('helio_msgs.' + kind), name)


@pytest.fixture
def private_context():
    """An rclpy Context of this test's own, shut down afterwards."""
    import rclpy
    from rclpy.context import Context
    context = Context()
    rclpy.init(context=context)
    try:
        yield context
    finally:
        context.try_shutdown()
