"""Secured profile: a private CA and one certificate per identity for Zenoh mutual TLS."""
