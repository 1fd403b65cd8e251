//! Rules over the checked bodies as a whole: what the body walk records ([`crate::typed`])
//! judged once every body has been walked.
//!
//! Today that is the recursion rule: IEC 61131-3 forbids recursion, so the call graph between
//! user POUs (FUNCTION, FB, METHOD and ACTION calls, recorded while the bodies are checked)
//! must have no cycle. Every POU gets one static frame because of it.

use crate::codes;
use crate::diagnostics::{Diagnostics, Span};
use crate::sema::Program;

/// A call in a body: the calling POU, the called POU and the call's span.
pub type CallEdge = (usize, usize, Span);

/// Reports the first call that closes a cycle of the call graph (one diagnostic at most).
pub fn check_recursion(prog: &Program, calls: &[CallEdge], diags: &mut Diagnostics) {
    let n = prog.pous.len();
    let mut adj = vec![Vec::new(); n];
    for &(a, b, span) in calls {
        adj[a].push((b, span));
    }
    // Depth-first search for a cycle; report the call that closes it.
    let mut state = vec![0u8; n];
    for v in 0..n {
        if state[v] == 0 {
            let mut found = None;
            dfs(v, &adj, &mut state, &mut found);
            if let Some((w, span)) = found {
                let name = &prog.pous[w].text;
                diags.error(
                    codes::RECURSION,
                    span,
                    format!("recursive call of `{name}` (IEC 61131-3 forbids recursion)"),
                );
                return;
            }
        }
    }
}

/// Depth-first walk from `v` (state 0 unvisited, 1 on the path, 2 done) that stops at the
/// first edge back onto the path.
fn dfs(v: usize, adj: &[Vec<(usize, Span)>], state: &mut [u8], found: &mut Option<(usize, Span)>) {
    state[v] = 1;
    for &(w, span) in &adj[v] {
        if found.is_some() {
            return;
        }
        if state[w] == 1 {
            *found = Some((w, span));
            return;
        }
        if state[w] == 0 {
            dfs(w, adj, state, found);
        }
    }
    state[v] = 2;
}
