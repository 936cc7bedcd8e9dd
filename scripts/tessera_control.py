#!/usr/bin/env python3
"""A client of a live run's control port (`tessera render MODEL --control HOST:PORT`), with
the Python standard library only. The port speaks newline-delimited JSON, one command a line,
each answered with one line (docs/guide.md, "Control port").

As a module:

    from tessera_control import Control
    with Control("127.0.0.1", 7070) as c:
        c.camera(eye=[0.1, 0.25, 0.4], target=[0.0, 0.1, 0.0])
        for _ in range(36):
            c.orbit(10)
        c.snapshot("/tmp/view.png")
        for line in c.stats(frames=5):   # the next 5 frames' rank 0 stats lines
            print(line["frame"], line["sort_ms"])
        c.quit()

From a shell, one command per argument, each a JSON object or a short form:

    scripts/tessera_control.py 127.0.0.1:7070 status 'orbit 15' 'snapshot /tmp/a.png' quit
    scripts/tessera_control.py --token-file token.txt 10.0.0.5:7070 status
"""
import json
import socket
import sys


class ControlError(Exception):
    """The run answered a command with an error line."""


class Control:
    def __init__(self, host, port, token=None, timeout=120.0):
        self.sock = socket.create_connection((host, port), timeout=timeout)
        self.lines = self.sock.makefile("r", encoding="utf-8")
        if token is not None:
            self.ask({"token": token})

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def close(self):
        self.lines.close()
        self.sock.close()

    def send(self, command):
        self.sock.sendall((json.dumps(command) + "\n").encode("utf-8"))

    def read(self):
        line = self.lines.readline()
        if not line:
            raise ControlError("the control port closed the connection")
        return json.loads(line)

    def ask(self, command):
        """Sends one command; its answer, or ControlError with the run's message."""
        self.send(command)
        answer = self.read()
        if "error" in answer:
            raise ControlError(answer["error"])
        return answer

    def camera(self, eye=None, target=None, up=None, fovy=None):
        command = {"cmd": "camera"}
        for key, value in (("eye", eye), ("target", target), ("up", up), ("fovy", fovy)):
            if value is not None:
                command[key] = value
        return self.ask(command)

    def orbit(self, degrees):
        return self.ask({"cmd": "orbit", "degrees": degrees})

    def snapshot(self, path):
        return self.ask({"cmd": "snapshot", "path": path})

    def status(self):
        return self.ask({"cmd": "status"})

    def stats(self, frames):
        """Subscribes (once per connection) and yields the next `frames` stats lines."""
        if not getattr(self, "_subscribed", False):
            self.ask({"cmd": "subscribe"})
            self._subscribed = True
        for _ in range(frames):
            yield self.read()

    def quit(self):
        return self.ask({"cmd": "quit"})


def short_form(text):
    """`orbit 15`, `snapshot PATH`, `status`, `quit`, or a JSON object."""
    text = text.strip()
    if text.startswith("{"):
        return json.loads(text)
    word, _, rest = text.partition(" ")
    if word == "orbit":
        return {"cmd": "orbit", "degrees": float(rest)}
    if word == "snapshot":
        return {"cmd": "snapshot", "path": rest}
    return {"cmd": word}


def main(argv):
    token = None
    if len(argv) > 2 and argv[1] == "--token-file":
        with open(argv[2], encoding="utf-8") as f:
            token = f.readline().strip()
        argv = argv[:1] + argv[3:]
    if len(argv) < 3:
        print(__doc__, file=sys.stderr)
        return 2
    host, _, port = argv[1].rpartition(":")
    try:
        with Control(host, int(port), token=token) as c:
            for text in argv[2:]:
                print(json.dumps(c.ask(short_form(text))))
    except (OSError, ControlError, ValueError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
