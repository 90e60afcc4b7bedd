//! Hostile dataset files (a pickle whose shared lists would expand without bound).

use crate::common::hostile::*;

#[test]
fn pickle_shared_list_bomb_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    // Protocol 2: L0 = []; L(k+1) = [Lk, Lk] via the memo; 40 levels = 2^40 values expanded.
    let mut b = vec![0x80, 2, b']', b'q', 0];
    for k in 0..40u8 {
        b.extend_from_slice(&[
            b']',
            b'q',
            k + 1,
            b'(',
            b'h',
            k,
            b'h',
            k,
            b'e',
            b'0',
            b'h',
            k + 1,
        ]);
    }
    b.push(b'.');
    let p = dir.path().join("bomb.pickle");
    std::fs::write(&p, &b).unwrap();
    let out = dir.path().join("out");
    assert_error(
        &["data", "import", "--pickle", &s(&p), "--out", &s(&out)],
        "bomb.pickle",
        &["pickle", "values"],
    );
}
