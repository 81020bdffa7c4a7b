//! The SDK's counting allocator, in a program of its own (the SDK's unit tests link two
//! copies of it, so they cannot have it as their allocator).
#![cfg(feature = "count-allocs")]
#![allow(clippy::unwrap_used, clippy::expect_used)]

use skill_sdk::allocs::thread_allocs;

#[test]
fn a_thread_counts_its_own_allocations_only() {
    let before = thread_allocs().unwrap();
    let v: Vec<u64> = std::hint::black_box(Vec::with_capacity(16));
    let mut s = String::new();
    s.push_str(std::hint::black_box("grows"));
    let after = thread_allocs().unwrap();
    assert_eq!(after - before, 2, "one Vec and one String");
    drop((v, s));
    assert_eq!(thread_allocs().unwrap(), after, "frees are not counted");
    // A thread that allocates n boxes counts n; the thread that started it counts the same
    // for any n (what starting a thread costs it), none of the boxes.
    let run = |n: usize| {
        let start = thread_allocs().unwrap();
        let counted = std::thread::spawn(move || {
            let start = thread_allocs().unwrap();
            for i in 0..n {
                drop(std::hint::black_box(Box::new(i)));
            }
            thread_allocs().unwrap() - start
        })
        .join()
        .unwrap();
        (counted, thread_allocs().unwrap() - start)
    };
    run(0); // (a first thread may set up what later ones share)
    let (none, spawning) = run(0);
    assert_eq!(none, 0);
    assert_eq!(
        run(100),
        (100, spawning),
        "another thread's allocations are its own"
    );
}

#[test]
fn arithmetic_and_a_stack_buffer_do_not_allocate() {
    let before = thread_allocs().unwrap();
    let mut buf = [0u8; 64];
    for (i, b) in buf.iter_mut().enumerate() {
        *b = (i as u8).wrapping_mul(3);
    }
    std::hint::black_box(&buf);
    assert_eq!(thread_allocs().unwrap(), before);
}
