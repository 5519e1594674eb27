"""The sandbox's pieces: refusing without bubblewrap, the view it builds, the method pipe's format.

The attacks themselves are the ``test_lb_hostile_*`` files; these are the rules behind them.
"""

from __future__ import annotations

from pathlib import Path

import lb_helpers as H
import numpy as np
import pytest

from swarmloc.leaderboard.verify import sandbox
from swarmloc.leaderboard.errors import SandboxUnavailable
from swarmloc.bench.evaluation.remote_method import MethodProtocolError, decode_reply, encode_reply
from swarmloc.leaderboard.store.database import LeaderboardStore
from swarmloc.leaderboard.submit.pipeline import submit


def test_without_bubblewrap_submit_refuses_and_names_the_opt_in(tmp_path: Path,
                                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    url = f"sqlite:///{tmp_path / 'lb.db'}"
    path = H.make_results_file(tmp_path / "r.json", "lb_fake_runner:good_nobwrap")
    options = H.submit_options(url) | {"sandbox": True}
    monkeypatch.setattr(sandbox, "BWRAP", "bwrap-not-installed")
    refusal = (r"bubblewrap \('bwrap-not-installed'\), which is not on PATH; install it "
               r"\(Debian/Ubuntu: apt-get install bubblewrap.*--no-sandbox")
    with pytest.raises(SandboxUnavailable, match=refusal):
        submit(path, "lb_fake_runner:good_nobwrap", {"name": "x", "track": "A"}, **options)
    with LeaderboardStore(url) as store:
        assert store.count() == 0
    receipt = submit(path, "lb_fake_runner:good_nobwrap", {"name": "x", "track": "A"},
                     **(options | {"sandbox": False}))
    assert receipt.report is not None and receipt.report.ok


def test_a_view_that_would_show_a_protected_path_is_refused(tmp_path: Path) -> None:
    store_file = tmp_path / "lb.db"
    view = sandbox.view_for([tmp_path], store_file)
    with pytest.raises(SandboxUnavailable, match=rf"would show {store_file} to the submitted code: it lies inside "
                                                 rf"{tmp_path}"):
        view.check()
    with pytest.raises(SandboxUnavailable, match=r"would show /tmp to the submitted code: it is a folder"):
        sandbox.view_for([Path("/tmp")]).check()
    with pytest.raises(SandboxUnavailable, match=rf"would show {Path.home()}"):
        sandbox.view_for([Path.home()]).check()
    sandbox.view_for([tmp_path / "methods"], store_file).check()  # a sibling folder is fine


def test_the_view_holds_python_swarmloc_and_the_extras_only(tmp_path: Path) -> None:
    method = tmp_path / "m.py"
    method.write_text("")
    view = sandbox.view_for([method])
    assert method in view.readable and tmp_path not in view.readable
    assert any(Path(sandbox.__file__).is_relative_to(p) for p in view.readable)
    assert not any(p == Path.home() or Path.home().is_relative_to(p) for p in view.readable)
    command = sandbox.sandbox_command(["true"], view)
    try:
        argv = command.argv
        assert argv[argv.index("--") + 1:][-1] == "true"
        for flag in ("--unshare-pid", "--unshare-net", "--die-with-parent", "--new-session"):
            assert flag in argv
        assert argv[argv.index("--remount-ro") + 1] == "/"
        binds = {argv[i + 2] for i, a in enumerate(argv) if a == "--ro-bind"}
        assert str(method) in binds and str(tmp_path) not in binds
    finally:
        command.close()


def test_limits_are_validated() -> None:
    with pytest.raises(ValueError, match="tmp_bytes must be at least 1 MiB, got 10"):
        sandbox.SandboxLimits(tmp_bytes=10)
    from swarmloc.leaderboard.verify.verification import VerifyLimits

    with pytest.raises(ValueError, match="max_processes must be at least 16, got 2"):
        VerifyLimits(max_processes=2)
    with pytest.raises(ValueError, match="max_file_bytes must be at least 1 MiB, got 0"):
        VerifyLimits(max_file_bytes=0)


def test_replies_from_the_method_are_decoded_without_pickle() -> None:
    header, arrays = decode_reply(encode_reply({"ok": True}, [np.arange(6.0).reshape(2, 3), None]))
    assert header["ok"] is True and arrays[1] is None and arrays[0].tolist() == [[0, 1, 2], [3, 4, 5]]
    with pytest.raises(MethodProtocolError, match="dtype <U1; only boolean and numeric arrays are allowed"):
        decode_reply(encode_reply({"ok": True}, [np.array(["x"])]))
    with pytest.raises(MethodProtocolError, match="malformed reply"):
        decode_reply(b"\x00\x00\x00\x02[]")
    with pytest.raises(MethodProtocolError, match="does not fit"):
        decode_reply(encode_reply({"ok": True}, [np.zeros(3)])[:-8])
    pickled = encode_reply({"ok": True}, [np.zeros(1)]).replace(b"'descr': '<f8'", b"'descr': '|O'")
    with pytest.raises(MethodProtocolError, match="malformed reply"):
        decode_reply(pickled)  # an object array would need pickle: refused
