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

#[cfg(test)]
mod tests {
    use super::split_lengths;

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
