use super::*;
use crate::lexer::lex;

fn parse_src(s: &str) -> (Unit, Vec<Diagnostic>) {
    let mut d = Vec::new();
    let t = lex(0, s, &mut d);
    let u = parse(t, &mut d);
    (u, d)
}

#[test]
fn precedence() {
    let (u, d) = parse_src("PROGRAM P VAR x : INT; END_VAR x := -2 ** 2 + 3 * 4; END_PROGRAM");
    assert!(d.is_empty(), "{d:?}");
    let StmtKind::Assign { value, .. } = &u.pous[0].body[0].kind else {
        panic!()
    };
    let ExprKind::Binary(BinOp::Add, l, _) = &value.kind else {
        panic!("{value:?}")
    };
    assert!(matches!(l.kind, ExprKind::Unary(UnOp::Neg, _)));
}

#[test]
fn partial_access_forms() {
    let (u, d) = parse_src("PROGRAM P x.3 := x.%B1.%X2; END_PROGRAM");
    assert!(d.is_empty(), "{d:?}");
    let StmtKind::Assign { target, value } = &u.pous[0].body[0].kind else {
        panic!()
    };
    assert!(matches!(
        target.kind,
        ExprKind::Bits {
            width: 1,
            index: 3,
            ..
        }
    ));
    let ExprKind::Bits {
        base,
        width: 1,
        index: 2,
    } = &value.kind
    else {
        panic!("{value:?}")
    };
    assert!(matches!(
        base.kind,
        ExprKind::Bits {
            width: 8,
            index: 1,
            ..
        }
    ));
    for bad in [
        "x.% := 1;",
        "x.%Q1 := 1;",
        "x.%B := 1;",
        "x.%X99999999999 := 1;",
    ] {
        let (_, d) = parse_src(&format!("PROGRAM P {bad} END_PROGRAM"));
        assert_eq!(d.len(), 1, "{bad}: {d:?}");
    }
}

#[test]
fn recovers_multiple_errors() {
    let (_, d) =
        parse_src("PROGRAM P\nVAR x : INT; END_VAR\nx := ;\nx := 1 +;\nx := 2;\nEND_PROGRAM");
    assert_eq!(d.len(), 2, "{d:?}");
}
