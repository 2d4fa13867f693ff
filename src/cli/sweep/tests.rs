use super::*;

#[test]
fn pareto_front_keeps_the_undominated() {
    let points = [
        (1.0, 5.0),
        (2.0, 3.0),
        (3.0, 4.0),
        (4.0, 1.0),
        (2.0, 3.0),
        (f64::NAN, 0.0),
    ];
    assert_eq!(
        pareto_front(&points),
        vec![true, true, false, true, true, false]
    );
}

#[test]
fn tick_labels_are_short() {
    assert_eq!(short_number(0.30000000000000004), "0.3");
    assert_eq!(short_number(1.25), "1.25");
    assert_eq!(short_number(12.0), "12");
    assert_eq!(short_number(0.0125), "0.0125");
    assert_eq!(short_number(2000.0), "2000");
}

#[test]
fn lists_parse_and_reject() {
    let l = parse_list("bins", "6, 8,preset,8", true, parse_count).unwrap();
    assert_eq!(l, vec![Choice::Value(6), Choice::Value(8), Choice::Preset]);
    assert!(parse_list("bins", "6,,8", true, parse_count).is_err());
    assert!(parse_list("bins", "preset", false, parse_count).is_err());
    assert!(parse_list("epsilon", "0.1,nan", true, parse_number).is_err());
    assert_eq!(
        parse_list("direct-light", "on,OFF,1", false, parse_switch).unwrap(),
        vec![Choice::Value(true), Choice::Value(false)]
    );
}
