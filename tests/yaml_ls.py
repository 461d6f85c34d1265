"""A headless client of the YAML language server (the one VS Code YAML and other editors run), for the tests.

It speaks LSP over the server's stdin/stdout: ``initialize``, ``didOpen``,
then it collects ``textDocument/publishDiagnostics`` and answers completion and
hover requests. The server is found through ``BEASTBT_YAML_LANGUAGE_SERVER``
(the ``yaml-language-server`` program, or a folder with
``node_modules/.bin/yaml-language-server`` in it, as ``npm install
yaml-language-server`` leaves it) or on the PATH; without it, or without
``node``, :func:`find_server` returns None and the tests that need it skip.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import threading
from pathlib import Path
from typing import Any, Optional

ENV = "BEASTBT_YAML_LANGUAGE_SERVER"
SETTINGS = {"yaml": {"validate": True, "hover": True, "completion": True, "format": {"enable": False},
                     "schemaStore": {"enable": False}}}
"""The settings an editor would send; the schema store is off (no network: schemas come from the files' own lines)."""


def find_server() -> Optional[str]:
    """The yaml-language-server program to run, or None."""
    if shutil.which("node") is None:
        return None
    given = os.environ.get(ENV, "")
    if given:
        path = Path(given)
        for candidate in (path, path / "node_modules" / ".bin" / "yaml-language-server",
                          path / ".bin" / "yaml-language-server"):
            if candidate.is_file() and os.access(candidate, os.X_OK):
                return str(candidate)
        return None
    return shutil.which("yaml-language-server")


class YamlLanguageServer:
    """One running server; use as a context manager."""

    def __init__(self, program: str, root: Path, timeout: float = 30.0) -> None:
        self.root = root
        self.timeout = timeout
        self.proc = subprocess.Popen([program, "--stdio"], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                     stderr=subprocess.DEVNULL, cwd=str(root))
        self._lock = threading.Condition()
        self._responses: dict[int, dict] = {}
        self._diagnostics: dict[str, list[dict]] = {}
        self._next_id = 0
        self._versions: dict[str, int] = {}
        threading.Thread(target=self._read, daemon=True).start()

    # -- the wire ---------------------------------------------------------------------------------------------
    def _send(self, message: dict) -> None:
        body = json.dumps(message).encode("utf-8")
        assert self.proc.stdin is not None
        self.proc.stdin.write(b"Content-Length: %d\r\n\r\n" % len(body) + body)
        self.proc.stdin.flush()

    def _read(self) -> None:
        out = self.proc.stdout
        assert out is not None
        while True:
            length = None
            while True:
                line = out.readline()
                if not line:
                    with self._lock:
                        self._lock.notify_all()
                    return
                line = line.strip()
                if not line:
                    break
                name, _, value = line.decode("ascii").partition(":")
                if name.lower() == "content-length":
                    length = int(value)
            if length is None:
                continue
            message = json.loads(out.read(length))
            if "method" in message and "id" in message:  # a request of the server's
                self._send({"jsonrpc": "2.0", "id": message["id"], "result": self._answer(message)})
            elif message.get("method") == "textDocument/publishDiagnostics":
                with self._lock:
                    self._diagnostics[message["params"]["uri"]] = message["params"]["diagnostics"]
                    self._lock.notify_all()
            elif "id" in message:
                with self._lock:
                    self._responses[message["id"]] = message
                    self._lock.notify_all()

    @staticmethod
    def _answer(message: dict) -> Any:
        if message["method"] == "workspace/configuration":
            return [SETTINGS.get(item.get("section", ""), None) for item in message["params"]["items"]]
        return None

    def request(self, method: str, params: dict) -> Any:
        with self._lock:
            self._next_id += 1
            ident = self._next_id
        self._send({"jsonrpc": "2.0", "id": ident, "method": method, "params": params})
        with self._lock:
            if not self._lock.wait_for(lambda: ident in self._responses or self.proc.poll() is not None, self.timeout):
                raise TimeoutError(f"no answer to {method} in {self.timeout} s")
            if ident not in self._responses:
                raise RuntimeError("the YAML language server has ended")
            response = self._responses.pop(ident)
        if "error" in response:
            raise RuntimeError(f"{method}: {response['error']}")
        return response.get("result")

    def notify(self, method: str, params: dict) -> None:
        self._send({"jsonrpc": "2.0", "method": method, "params": params})

    # -- what an editor does ----------------------------------------------------------------------------------
    def __enter__(self) -> "YamlLanguageServer":
        self.request("initialize", {
            "processId": os.getpid(), "rootUri": self.root.as_uri(),
            "workspaceFolders": [{"uri": self.root.as_uri(), "name": self.root.name}],
            "capabilities": {"workspace": {"configuration": True},
                             "textDocument": {"completion": {"completionItem": {
                                 "snippetSupport": True, "documentationFormat": ["markdown", "plaintext"]}},
                                 "hover": {"contentFormat": ["markdown", "plaintext"]}}}})
        self.notify("initialized", {})
        self.notify("workspace/didChangeConfiguration", {"settings": SETTINGS})
        return self

    def __exit__(self, *exc: Any) -> None:
        try:
            self.request("shutdown", {})
            self.notify("exit", {})
            self.proc.wait(timeout=5)
        except Exception:  # noqa: BLE001 - a server that will not stop is stopped
            self.proc.kill()
            self.proc.wait()

    def open(self, path: Path, text: Optional[str] = None) -> str:
        """Open ``path`` (with ``text``, or its content on disk) as an editor does; return its URI."""
        uri = path.resolve().as_uri()
        if text is None:
            text = path.read_text(encoding="utf-8")
        with self._lock:
            self._diagnostics.pop(uri, None)
            version = self._versions[uri] = self._versions.get(uri, 0) + 1
        if version == 1:
            self.notify("textDocument/didOpen", {"textDocument": {"uri": uri, "languageId": "yaml", "version": version,
                                                                  "text": text}})
        else:
            self.notify("textDocument/didChange", {"textDocument": {"uri": uri, "version": version},
                                                   "contentChanges": [{"text": text}]})
        return uri

    def diagnostics(self, uri: str) -> list[dict]:
        """The problems the server reports for the document (waits for its first report after the last change)."""
        with self._lock:
            if not self._lock.wait_for(lambda: uri in self._diagnostics or self.proc.poll() is not None, self.timeout):
                raise TimeoutError(f"no diagnostics for {uri} in {self.timeout} s")
            return self._diagnostics.get(uri, [])

    def completion(self, uri: str, line: int, character: int) -> list[dict]:
        result = self.request("textDocument/completion", {"textDocument": {"uri": uri},
                                                          "position": {"line": line, "character": character}})
        return result.get("items", []) if isinstance(result, dict) else (result or [])

    def hover(self, uri: str, line: int, character: int) -> str:
        result = self.request("textDocument/hover", {"textDocument": {"uri": uri},
                                                     "position": {"line": line, "character": character}})
        if not result:
            return ""
        contents = result["contents"]
        return contents.get("value", "") if isinstance(contents, dict) else str(contents)


def text_of(documentation: Any) -> str:
    """A completion item's documentation as text (it is a string or a markup object)."""
    if isinstance(documentation, dict):
        return str(documentation.get("value", ""))
    return str(documentation or "")
