//! The greedy against the exact optimum: a table of every `exact` run.

use std::fmt::Write as _;

use super::*;

impl Page<'_> {
    /// The greedy against the exact optimum, for every `exact` run: how the
    /// solver ended, the greedy's memory and the optimum's (or the best
    /// found and the proven lower bound), and their ratio. Nothing when no
    /// run is `exact`.
    pub(super) fn exact_table(&self, h: &mut String) {
        let runs: Vec<&Run> = self.r.runs.iter().filter(|x| x.exact.is_some()).collect();
        if runs.is_empty() {
            return;
        }
        section_start(h, "exact", "The greedy against the exact optimum");
        h.push_str(
            "<p>The <code>exact</code> method solves the greedy's problem (the shafts' \
             candidates, every problem view within the target, least memory) as an integer \
             program seeded with the greedy's selection. Where the solver stopped at a limit, \
             the lower bound says how far the optimum can still be below what it found.</p>\n\
             <table><tr><th>setting</th><th>solver</th><th>nodes</th><th>seconds</th>\
             <th>greedy, MB</th><th>exact, MB</th><th>lower bound, MB</th>\
             <th>greedy / exact</th></tr>\n",
        );
        for x in runs {
            let e = x.exact.as_ref().expect("filtered");
            let bound = e
                .lower_bound_bytes
                .map_or("–".to_string(), |b| format!("{:.4}", mb(b)));
            let _ = writeln!(
                h,
                "<tr><td>{}</td><td>{}</td><td class=\"n\">{}</td><td class=\"n\">{:.2}</td>\
                 <td class=\"n\">{:.4}</td><td class=\"n\">{:.4}</td><td class=\"n\">{}</td>\
                 <td class=\"n\">{:.3}</td></tr>",
                esc(&setting(x)),
                esc(&e.status),
                e.nodes,
                e.seconds,
                mb(e.greedy_memory_bytes),
                mb(e.memory_bytes),
                bound,
                e.greedy_over_exact
            );
        }
        h.push_str("</table>\n");
    }
}
