//! A few thousand cases of the mutation fuzzer per target (the `fuzz`
//! example runs 100,000): no parser of a user's file may panic.

#[path = "../optimizer/examples/fuzz/engine.rs"]
mod engine;

#[test]
fn mutated_inputs_never_panic() {
    for o in engine::run(2_000, 7) {
        assert!(
            o.panic.is_none(),
            "{}: case {} panicked; input {:?}",
            o.name,
            o.cases,
            o.panic.map(|p| String::from_utf8_lossy(&p.1).into_owned())
        );
        assert_eq!(o.cases, 2_000, "{}", o.name);
        // A hang, not a speed target: the slowest case takes milliseconds.
        assert!(
            o.slowest < 10.0,
            "{}: a case ran {:.1} s ({:.1} s in all)",
            o.name,
            o.slowest,
            o.seconds
        );
    }
}
