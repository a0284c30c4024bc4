//! Buffers a frame's choice keeps from one frame to the next, made ready
//! before the first frame fills them.

use std::mem::MaybeUninit;

/// Reserves room for `n` more in `v` and writes its spare memory once, so
/// that its pages are the process's before a frame fills them: a choice
/// that first touches fresh memory waits on each new page.
pub fn touched<T>(v: &mut Vec<T>, n: usize) {
    v.reserve(n);
    v.spare_capacity_mut()
        .iter_mut()
        .for_each(|slot| *slot = MaybeUninit::zeroed());
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Touching reserves room without changing what a buffer holds.
    #[test]
    fn touched_buffers_have_room_and_keep_their_contents() {
        let mut v = vec![3u32, 1, 4];
        touched(&mut v, 1000);
        assert_eq!(v, [3, 1, 4]);
        assert!(v.capacity() >= 1003);
    }
}
