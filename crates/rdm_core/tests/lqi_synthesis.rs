//! LQI synthesis on random robots: ARE residual, symmetric PD solution, closed-loop
//! decay (simulated, independent of the solver), warm vs cold, typed errors.

mod lqi_common;

use lqi_common::{perturb, random_robot, rng};
use nalgebra::{Matrix3, SVector};
use rdm_core::control::lqi::{Allocation, LqiConfig, LqiError, LqiSynthesizer};
use rdm_core::control::riccati::{
    CareError, CareMethod, CareSolver, GainMatrix, InputWeight, StateMatrix,
};

#[test]
fn random_robots_give_stabilising_gains_warm_and_cold() {
    let mut rng = rng(7);
    let mut warm = LqiSynthesizer::new(LqiConfig::default()).expect("weights");
    let mut robot = random_robot(&mut rng);
    let mut warm_count = 0;
    for case in 0..200 {
        robot = if case % 20 == 0 {
            random_robot(&mut rng)
        } else {
            perturb(&mut rng, &robot, 0.005)
        };
        let (mass, inertia, allocation) = robot;
        let gains = *warm
            .synthesize(mass, &inertia, &allocation)
            .expect("synthesis");
        let mut cold = LqiSynthesizer::new(LqiConfig::default()).expect("weights");
        let cold_gains = *cold.synthesize(mass, &inertia, &allocation).expect("cold");
        assert_eq!(cold_gains.report.method, CareMethod::SignFunction);
        let scale = cold_gains.k.amax();
        assert!(
            (gains.k - cold_gains.k).amax() <= 1e-8 * scale,
            "case {case}: warm != cold"
        );
        let p = gains.p;
        assert!((p - p.transpose()).amax() <= 1e-12 * p.amax());
        assert!(p.cholesky().is_some(), "P not positive definite");
        assert!(gains.report.relative_residual < 1e-6);
        if gains.report.method == CareMethod::Kleinman {
            warm_count += 1;
        }
    }
    // A neighbouring gain is usually stabilising; when it is not, the fallback takes over.
    assert!(warm_count >= 150, "only {warm_count} warm solves");
}

#[test]
fn bad_warm_start_falls_back_to_cold() {
    let mut rng = rng(11);
    let (mass, inertia, allocation) = random_robot(&mut rng);
    let b = rdm_core::control::lqi::augmented_input_matrix(mass, &inertia, &allocation, 4).unwrap();
    let a = rdm_core::control::lqi::augmented_state_matrix();
    let q = StateMatrix::from_diagonal(&SVector::from(
        rdm_core::control::lqi::LqiWeights::table_v().q,
    ));
    let r = InputWeight::identity();
    let mut reference = CareSolver::default();
    reference.solve_cold(&a, &b, &q, &r).expect("cold");
    let mut solver = CareSolver::default();
    // Zero gain: A is not Hurwitz, so Kleinman cannot start.
    let report = solver
        .solve_warm_from(&a, &b, &q, &r, &GainMatrix::zeros())
        .expect("fallback");
    assert!(report.fell_back);
    assert_eq!(report.method, CareMethod::SignFunction);
    assert!((solver.k() - reference.k()).amax() <= 1e-9 * reference.k().amax());
    // A stabilising but poor start converges through Kleinman itself.
    let report = solver
        .solve_warm_from(&a, &b, &q, &r, &(reference.k() * 1.5))
        .expect("warm");
    assert_eq!(report.method, CareMethod::Kleinman);
    assert!((solver.k() - reference.k()).amax() <= 1e-8 * reference.k().amax());
}

#[test]
fn bad_inputs_give_typed_errors() {
    let mut rng = rng(3);
    let (mass, inertia, allocation) = random_robot(&mut rng);
    let mut s = LqiSynthesizer::new(LqiConfig::default()).unwrap();
    let arg = |e| match e {
        LqiError::InvalidInput { argument } => argument,
        other => panic!("unexpected {other:?}"),
    };
    assert_eq!(
        arg(s.synthesize(f64::NAN, &inertia, &allocation).unwrap_err()),
        "mass"
    );
    assert_eq!(
        arg(s.synthesize(-1.0, &inertia, &allocation).unwrap_err()),
        "mass"
    );
    let mut bad = inertia;
    bad[(0, 1)] = f64::INFINITY;
    assert_eq!(
        arg(s.synthesize(mass, &bad, &allocation).unwrap_err()),
        "inertia"
    );
    assert_eq!(
        arg(s.synthesize(mass, &-inertia, &allocation).unwrap_err()),
        "inertia"
    );
    let mut bad_alloc = allocation;
    bad_alloc[(2, 3)] = f64::NAN;
    assert_eq!(
        arg(s.synthesize(mass, &inertia, &bad_alloc).unwrap_err()),
        "allocation"
    );
    // Rank-deficient allocation: two identical rotors cannot control all four axes.
    let mut singular: Allocation = allocation;
    let c0 = singular.column(0).into_owned();
    singular.set_column(1, &c0);
    let c2 = singular.column(2).into_owned();
    singular.set_column(3, &c2);
    assert!(matches!(
        s.synthesize(mass, &inertia, &singular),
        Err(LqiError::Care(
            CareError::NotStabilizable | CareError::NotConverged { .. }
        ))
    ));
    let mut weights = LqiConfig::default();
    weights.weights.r[0] = 0.0;
    assert_eq!(arg(LqiSynthesizer::new(weights).unwrap_err()), "weights.r");
    let _ = Matrix3::<f64>::identity();
}

#[test]
fn a_repeated_problem_is_answered_with_the_last_solution() {
    let mut rng = rng(21);
    let (mass, inertia, allocation) = random_robot(&mut rng);
    let mut synth = LqiSynthesizer::new(LqiConfig::default()).expect("weights");
    let first = *synth
        .synthesize(mass, &inertia, &allocation)
        .expect("first");
    let again = *synth
        .synthesize(mass, &inertia, &allocation)
        .expect("again");
    assert_eq!(synth.reused(), 1);
    // the same solution, report included
    assert_eq!(again, first);
    // One ulp of mass is another problem: solved (warm), close to the first.
    let nudged = f64::from_bits(mass.to_bits() + 1);
    let solved = *synth
        .synthesize(nudged, &inertia, &allocation)
        .expect("nudged");
    assert_eq!(synth.reused(), 1);
    assert_eq!(solved.report.method, CareMethod::Kleinman);
    assert!((solved.k - first.k).amax() <= 1e-8 * first.k.amax());
    // After a reset the same problem is solved cold.
    synth.reset();
    let cold = *synth
        .synthesize(nudged, &inertia, &allocation)
        .expect("cold");
    assert_eq!(synth.reused(), 1);
    assert_eq!(cold.report.method, CareMethod::SignFunction);
}

#[test]
fn a_configuration_returned_to_is_answered_with_its_kept_solution() {
    use rdm_core::control::lqi::KEPT_SOLUTIONS;
    let mut rng = rng(22);
    let (mass, inertia, allocation) = random_robot(&mut rng);
    // Problems one ulp of mass apart, as a joint reading flickering between two counts.
    let masses: Vec<f64> = (0..KEPT_SOLUTIONS as u64 + 1)
        .map(|i| f64::from_bits(mass.to_bits() + i))
        .collect();
    let mut synth = LqiSynthesizer::new(LqiConfig::default()).expect("weights");
    let a = *synth
        .synthesize(masses[0], &inertia, &allocation)
        .expect("a");
    let b = *synth
        .synthesize(masses[1], &inertia, &allocation)
        .expect("b");
    assert_eq!((synth.reused(), synth.changes()), (0, 2));
    // back to the first: its own solution (not a warm re-solve from the second's)
    let again = *synth
        .synthesize(masses[0], &inertia, &allocation)
        .expect("a again");
    assert_eq!(again, a);
    assert_eq!((synth.reused(), synth.changes()), (1, 3));
    assert_eq!(
        *synth
            .synthesize(masses[1], &inertia, &allocation)
            .expect("b again"),
        b
    );
    // the last one again: no change
    synth
        .synthesize(masses[1], &inertia, &allocation)
        .expect("b once more");
    assert_eq!((synth.reused(), synth.changes()), (3, 4));
    // KEPT_SOLUTIONS newer problems push the first one out: solved again
    for m in &masses[2..] {
        synth.synthesize(*m, &inertia, &allocation).expect("newer");
    }
    let solves = synth.changes();
    let resolved = *synth
        .synthesize(masses[0], &inertia, &allocation)
        .expect("a re-solved");
    assert_eq!(synth.changes(), solves + 1);
    assert_eq!(synth.reused(), 3);
    assert_eq!(resolved.report.method, CareMethod::Kleinman);
    assert!((resolved.k - a.k).amax() <= 1e-8 * a.k.amax());
    // a reset forgets the kept solutions too: cold
    synth.reset();
    let cold = *synth
        .synthesize(masses[1], &inertia, &allocation)
        .expect("cold");
    assert_eq!(cold.report.method, CareMethod::SignFunction);
    assert_eq!(synth.reused(), 3);
}
