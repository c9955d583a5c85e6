//! Cutting one mutable slice into consecutive, disjoint pieces, so that threads can fill them
//! in parallel without locks or unsafe code.

/// Splits `s` into consecutive pieces of the given `lengths` (in order); returns the pieces
/// and what is left after them. Panics if the lengths add up to more than `s.len()`.
pub(crate) fn split_lengths<T>(
    mut s: &mut [T],
    lengths: impl IntoIterator<Item = usize>,
) -> (Vec<&mut [T]>, &mut [T]) {
    let lengths = lengths.into_iter();
    let mut pieces = Vec::with_capacity(lengths.size_hint().0);
    for n in lengths {
        let (piece, rest) = std::mem::take(&mut s).split_at_mut(n);
        pieces.push(piece);
        s = rest;
    }
    (pieces, s)
}

/// Makes room in `v` for `n` elements in all. Where it must grow, it grows to `n` and a
/// sixty-fourth more, not to the double that `Vec`'s amortised growth gives: a buffer rebuilt
/// every step whose contents grow by a few elements would otherwise keep up to twice what it
/// holds for the rest of the run.
pub(crate) fn reserve_total<T>(v: &mut Vec<T>, n: usize) {
    if v.capacity() < n {
        v.reserve_exact(n + n / 64 - v.len());
    }
}

/// Gives back the spare room of a buffer kept from step to step when it exceeds a quarter of
/// what it holds (after `Vec`'s amortised growth doubled it), keeping a sixteenth.
pub(crate) fn trim<T>(v: &mut Vec<T>) {
    let n = v.len();
    if v.capacity() > n + n / 4 + 16 {
        v.shrink_to(n + n / 16);
    }
}

#[cfg(test)]
mod tests {
    use super::{reserve_total, split_lengths, trim};

    #[test]
    fn a_buffer_grows_to_what_it_holds_and_a_little() {
        let mut v: Vec<u64> = Vec::new();
        for n in [6_400, 6_401, 6_450, 6_600, 3_000] {
            let before = v.capacity();
            reserve_total(&mut v, n);
            v.resize(n, 0);
            if before >= n {
                assert_eq!(v.capacity(), before, "room enough for {n}: unchanged");
            } else {
                assert!(
                    v.capacity() >= n && v.capacity() <= n + n / 64,
                    "{}",
                    v.capacity()
                );
            }
            v.clear();
        }
        // The amortised growth of `Vec` doubles for one element more; trimmed, a sixteenth
        // is left.
        let mut w: Vec<u64> = vec![0; 6_400];
        w.shrink_to_fit();
        w.push(0);
        assert!(w.capacity() >= 12_800);
        trim(&mut w);
        assert!(
            w.capacity() >= 6_401 && w.capacity() <= 6_401 + 400,
            "{}",
            w.capacity()
        );
        let kept = w.capacity();
        w.truncate(6_000);
        trim(&mut w);
        assert_eq!(w.capacity(), kept, "less than a quarter spare: kept");
    }

    #[test]
    fn pieces_are_consecutive_and_the_rest_is_returned() {
        let mut v: Vec<u32> = (0..10).collect();
        let (pieces, rest) = split_lengths(&mut v, [3, 0, 4]);
        assert_eq!(pieces.len(), 3);
        assert_eq!(&*pieces[0], &[0, 1, 2]);
        assert!(pieces[1].is_empty());
        assert_eq!(&*pieces[2], &[3, 4, 5, 6]);
        assert_eq!(rest, &[7, 8, 9]);
    }
}
