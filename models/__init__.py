"""MJCF models shipped with joints (installed as the package data ``joints.models``)."""
