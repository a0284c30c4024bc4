//! The GPU test harness itself: tests in one binary never have devices
//! open at the same time (`common::gpu`'s lock), since the validation
//! layer's map of devices is not safe to change while another thread
//! calls through it.

mod common;

use std::time::Instant;

use common::gpu::*;

/// Two threads each open a device, keep it a while and close it: the
/// second opens only once the first has closed, whichever goes first.
#[test]
fn devices_are_never_open_in_two_tests_at_once() {
    if skip_gpu() {
        return;
    }
    let spans: Vec<(Instant, Instant)> = (0..2)
        .map(|_| {
            std::thread::spawn(|| {
                let gpu = open_gpu(None);
                let opened = Instant::now();
                std::thread::sleep(std::time::Duration::from_millis(200));
                let report = gpu.shutdown();
                assert_eq!(report.count, 0, "{:?}", report.messages);
                (opened, Instant::now())
            })
        })
        .collect::<Vec<_>>()
        .into_iter()
        .map(|thread| thread.join().expect("a device thread"))
        .collect();
    let [(a_open, a_closed), (b_open, b_closed)] = spans[..] else {
        unreachable!("two threads")
    };
    assert!(
        a_closed <= b_open || b_closed <= a_open,
        "both devices open at once: {spans:?}"
    );
}
