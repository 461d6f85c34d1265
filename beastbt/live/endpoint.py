"""Parsing where a live server listens (``[HOST:]PORT``) and a frame size (``WxH``): light, for the command line."""

from __future__ import annotations


def parse_endpoint(text: str, option: str = "--stream") -> tuple[str, int]:
    """``PORT``, ``:PORT`` or ``HOST:PORT`` -> (host, port); the host defaults to 127.0.0.1.

    ``option`` names the command-line option in the error message.
    """
    text = str(text).strip()
    host, sep, port = text.rpartition(":")
    if not sep:
        host = ""
    host = host.strip("[]") or "127.0.0.1"
    try:
        number = int(port)
    except ValueError:
        raise ValueError(f"{option} takes [HOST:]PORT such as 8080 or 0.0.0.0:8080, not '{text}'") from None
    if not 0 <= number <= 65535:
        raise ValueError(f"{option} port must be 0..65535, not {number}")
    return host, number


def is_loopback(host: str) -> bool:
    """True for 127.0.0.0/8, ::1 and ``localhost``: only this computer can reach a server bound there."""
    import ipaddress
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def parse_size(text: str) -> tuple[int, int]:
    """``WIDTHxHEIGHT`` (``640x480``) -> (width, height) in pixels."""
    try:
        w, h = (int(v) for v in str(text).lower().split("x"))
    except ValueError:
        raise ValueError(f"--stream-size takes WIDTHxHEIGHT such as 640x480, not '{text}'") from None
    return w, h


__all__ = ["parse_endpoint", "parse_size", "is_loopback"]
