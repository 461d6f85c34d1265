"""The console's video wakes each viewer's sender on its event loop (no thread per viewer waits for frames): a
frame from any source calls the wakers once, the end calls them too, and a viewer can tell whether a newer
frame is already waiting (an H.264 viewer that skipped a unit waiting for a keyframe must not sleep on it)."""

from __future__ import annotations

import threading

from beastbt.live.console_video import HEADER, PASSED_THROUGH, ConsoleVideo, VideoConfig

JPEG = b"\xff\xd8 a camera's own JPEG \xff\xd9"


def video() -> ConsoleVideo:
    return ConsoleVideo(VideoConfig(), lambda: 0.0, lambda: 1_700_000_000.0, lambda: ["patrol  running  t 1.0 s"])


def test_a_cameras_jpeg_wakes_every_viewer_once_and_goes_out_as_it_came() -> None:
    v = video()
    woken = {"a": 0, "b": 0}
    wake_a, wake_b = (lambda: woken.__setitem__("a", woken["a"] + 1)), (lambda: woken.__setitem__("b", woken["b"] + 1))
    v.add_waker(wake_a)
    v.add_waker(wake_b)
    feed = v.feed()
    assert feed.next_message(0.0) is None and not feed.has_newer()
    v.pass_jpeg(JPEG, None, None, 0.25, 1_700_000_000.5)
    assert woken == {"a": 1, "b": 1}
    assert feed.has_newer()
    message = feed.next_message(0.0)
    assert message is not None and message.endswith(JPEG)
    captured_ms, seq, quality, overlay_length = HEADER.unpack_from(message)
    assert quality == PASSED_THROUGH and seq == 1 and captured_ms == 1_700_000_000.5 * 1000.0
    assert b"patrol  running" in message[HEADER.size:HEADER.size + overlay_length]
    assert not feed.has_newer() and feed.next_message(0.0) is None
    assert v.frames_passed == 1 and v.frames_encoded == 0  # nothing decoded or encoded here
    v.remove_waker(wake_a)
    v.pass_jpeg(JPEG, None, None, 0.25, 1_700_000_001.0)
    assert woken == {"a": 1, "b": 2}
    v.close()
    assert woken == {"a": 1, "b": 3}  # the end wakes the senders that are left, for good
    assert not feed.has_newer() and feed.next_message(0.0) is None


def test_the_overlay_is_made_again_when_the_caption_or_the_detection_changes() -> None:
    captions = [["t 1.0 s"]]
    v = ConsoleVideo(VideoConfig(), lambda: 0.0, lambda: 0.0, lambda: captions[0])
    first = v._overlay_bytes(None, None, 0.25)  # noqa: SLF001 - the cache is what is tested
    assert v._overlay_bytes(None, None, 0.25) is first  # noqa: SLF001
    captions[0] = ["t 1.1 s"]
    second = v._overlay_bytes(None, None, 0.25)  # noqa: SLF001
    assert b"t 1.1 s" in second and b"t 1.0 s" not in second


def test_a_viewer_made_on_another_thread_is_woken_from_that_thread() -> None:
    v = video()
    threads: list[str] = []
    v.add_waker(lambda: threads.append(threading.current_thread().name))
    maker = threading.Thread(target=v.pass_jpeg, args=(JPEG, None, None, 0.25, 0.0), name="pipe-reader")
    maker.start()
    maker.join()
    assert threads == ["pipe-reader"]  # the waker hands over to the loop itself (call_soon_threadsafe)
