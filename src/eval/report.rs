//! The evaluation's tables and plots: `results.csv`, `control_points.csv`, `report.md` and the
//! PNG plots, all written atomically. Numbers in the CSV files are written with full precision
//! (shortest round-trip form), so reruns can be compared byte for byte; empty fields mean "not
//! measured" (temporal STED of unordered data, locality of region PCA).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use super::plots::{Series, line_plot};
use super::{CellResult, ControlPointRow, EvalConfig, FailedCell};
use crate::artifact::write_atomic;
use crate::error::Result;

/// Header of `results.csv`.
pub const RESULTS_HEADER: &str = "dataset,method,representation,K,train_erms,test_erms,alignment,sted_spatial,sted_temporal,in_support_share,support_size,support_regions,seconds,test_erms_fitted,sted_spatial_fitted,sted_temporal_fitted,test_erms_one_pass,test_erms_network,validation_erms,vertex_support,recovery_found,recovery_counted,recovery_found_all,recovery_total,recovery_median_abs_cos,recovery_median_iou";

/// Header of `control_points.csv`.
pub const CONTROL_POINTS_HEADER: &str = "dataset,method,K,n,erms_mean,erms_min,erms_max,trials";

fn opt(x: Option<f64>) -> String {
    x.map(|v| v.to_string()).unwrap_or_default()
}

/// `results.csv` text.
pub fn results_csv(results: &[CellResult]) -> String {
    let mut s = format!("{RESULTS_HEADER}\n");
    for r in results {
        let _ = writeln!(
            s,
            "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}",
            r.dataset,
            r.method,
            r.representation,
            r.k,
            r.train_erms,
            r.test_erms,
            r.alignment,
            r.sted_spatial,
            opt(r.sted_temporal),
            opt(r.in_support_share),
            opt(r.support_size),
            opt(r.support_regions),
            r.seconds,
            opt(r.test_erms_fitted),
            opt(r.sted_spatial_fitted),
            opt(r.sted_temporal_fitted),
            opt(r.test_erms_one_pass),
            opt(r.test_erms_network),
            opt(r.validation_erms),
            opt(r.vertex_support),
            r.recovery.as_ref().map(|x| x.found.to_string()).unwrap_or_default(),
            r.recovery.as_ref().map(|x| x.counted.to_string()).unwrap_or_default(),
            r.recovery.as_ref().map(|x| x.found_all.to_string()).unwrap_or_default(),
            r.recovery.as_ref().map(|x| x.total.to_string()).unwrap_or_default(),
            opt(r.recovery.as_ref().map(|x| x.median_abs_cos)),
            opt(r.recovery.as_ref().map(|x| x.median_iou))
        );
    }
    s
}

/// Per dataset of `cfg` (in order), the index into `results` of its cell of lowest validation
/// Erms, when `cfg` selects on validation (`None` for a dataset without a measured cell).
pub fn chosen_on_validation(cfg: &EvalConfig, results: &[CellResult]) -> Vec<Option<usize>> {
    if !cfg.select_on_validation {
        return vec![None; cfg.datasets.len()];
    }
    cfg.datasets
        .iter()
        .map(|d| {
            results
                .iter()
                .enumerate()
                .filter(|(_, r)| r.dataset == d.name)
                .filter_map(|(i, r)| r.validation_erms.map(|v| (i, v)))
                .min_by(|a, b| a.1.total_cmp(&b.1))
                .map(|(i, _)| i)
        })
        .collect()
}

/// `control_points.csv` text.
pub fn control_points_csv(rows: &[ControlPointRow]) -> String {
    let mut s = format!("{CONTROL_POINTS_HEADER}\n");
    for r in rows {
        let e = &r.erms;
        let _ = writeln!(
            s,
            "{},{},{},{},{},{},{},{}",
            r.dataset, r.method, r.k, e.n, e.erms_mean, e.erms_min, e.erms_max, e.trials
        );
    }
    s
}

fn f(x: f64, digits: usize) -> String {
    format!("{x:.digits$}")
}

fn fo(x: Option<f64>, digits: usize) -> String {
    x.map(|v| f(v, digits)).unwrap_or_else(|| "–".into())
}

/// The recovery table and plot of a planted dataset (`truth = "DIR"`).
fn recovery_section(
    md: &mut String,
    files: &mut Vec<PathBuf>,
    out: &Path,
    d: &crate::eval::EvalDataset,
    rows: &[&CellResult],
) -> Result<()> {
    let truth: Option<crate::eval::planted::TruthFile> =
        d.truth.as_ref().and_then(|t| crate::artifact::read_json(&t.join(crate::eval::planted::TRUTH_FILE)).ok());
    let _ = writeln!(
        md,
        "### {}: recovery of the planted deformations
",
        d.name
    );
    if let Some(t) = &truth {
        let _ = writeln!(
            md,
            "{} deformations planted on `{}` ({} vertices), {} identifiable; noise {} of the diagonal. Test Erms of \
             the rest shape {:.3}; of the least-squares fit by the true fields (the oracle) {:.3}.\n",
            t.deformations.len(),
            t.source,
            t.n_vertices,
            t.identifiable,
            t.noise,
            t.rest_test_erms,
            t.oracle_test_erms
        );
    }
    md.push_str(
        "Per true deformation, the component whose vertex field (around the rest shape, dial +1) has the largest \
         |cos| with it; *found*: |cos| ≥ 0.9; medians over the identifiable ones; *sign*: share whose best \
         component's dial moves the way the deformation does; *vertex support*: median share of vertices a \
         component moves by more than 5 % of its peak.\n\n\
         | method | K | test Erms | found / identifiable | found / all | median \\|cos\\| | median IoU | sign | vertex support |\n\
         |---|---:|---:|---:|---:|---:|---:|---:|---:|\n",
    );
    let mut series = Vec::new();
    for r in rows {
        let Some(x) = &r.recovery else { continue };
        let _ = writeln!(
            md,
            "| {} | {} | {} | {} / {} | {} / {} | {} | {} | {} | {} |",
            r.method,
            r.k,
            f(r.test_erms, 3),
            x.found,
            x.counted,
            x.found_all,
            x.total,
            f(x.median_abs_cos, 3),
            f(x.median_iou, 3),
            f(x.positive, 2),
            r.vertex_support.map_or("–".into(), |v| format!("{:.1} %", 100.0 * v))
        );
        let path = crate::eval::cell_dir(out, &r.dataset, &r.method, r.k).join(crate::eval::RECOVERY_FILE);
        if let Ok(m) = crate::artifact::read_json::<Vec<crate::eval::DeformationMatch>>(&path) {
            let mut c: Vec<f64> = m.iter().filter(|m| m.identifiable).map(|m| m.best.abs_cos).collect();
            c.sort_by(|a, b| b.total_cmp(a));
            let points = c.iter().enumerate().map(|(i, v)| ((i + 1) as f64, *v)).collect();
            series.push(Series { label: format!("{} (K = {})", r.method, r.k), points });
        }
    }
    if !series.is_empty() {
        let png = format!("recovery_{}.png", d.name);
        line_plot(
            &out.join(&png),
            &format!("{}: best |cos| per true deformation, sorted", d.name),
            "true deformations (sorted)",
            "best |cos|",
            &series,
        )?;
        let _ = writeln!(md, "\n![recovery]({png})\n");
        files.push(out.join(png));
    }
    md.push('\n');
    Ok(())
}

/// Writes results.csv, control_points.csv (when there are rows), the plots and report.md into
/// `out`; returns the paths written.
pub fn write_all(
    cfg: &EvalConfig,
    out: &Path,
    results: &[CellResult],
    failed: &[FailedCell],
    cp: &[ControlPointRow],
) -> Result<Vec<PathBuf>> {
    std::fs::create_dir_all(out).map_err(|e| crate::Error::io(out, e))?;
    let mut files = Vec::new();
    let p = out.join("results.csv");
    write_atomic(&p, results_csv(results).as_bytes())?;
    files.push(p);
    let p = out.join("failed_cells.csv");
    if failed.is_empty() {
        let _ = std::fs::remove_file(&p);
    } else {
        let mut csv = String::from("dataset,method,K,error\n");
        for r in failed {
            let _ = writeln!(
                csv,
                "{},{},{},\"{}\"",
                r.dataset,
                r.method,
                r.k,
                r.error.replace('"', "\"\"").replace('\n', " ")
            );
        }
        write_atomic(&p, csv.as_bytes())?;
        files.push(p);
    }
    if !cp.is_empty() {
        let p = out.join("control_points.csv");
        write_atomic(&p, control_points_csv(cp).as_bytes())?;
        files.push(p);
    }

    let mut md = format!("# Evaluation `{}`\n\n", cfg.name);
    md.push_str(
        "Generated by `meshdeco eval` (do not edit by hand). Erms: 1000 × RMS vertex error in the data's \
         units, on the test split unless marked train; `alignment` centroid = result centroid moved onto the \
         ground truth's (translation-free representations). STED: spatial part (1-ring, edge-length weighted), \
         temporal part for ordered sequences (c = 0.5). Locality: medians over components of the in-support \
         energy share, the support size (elements above 1 % of the peak) and the number of connected support \
         regions. Seconds: fit time. Autoencoder rows: `test Erms`, `STED s`, `STED t` are the network \
         encoder's codes (with its residual passes where `encoder_passes` > 0 and its vertex steps where \
         `encoder_steps` > 0; `test Erms, network only`: without the steps; `test Erms, one pass`: the \
         network's one pass); the `fitted` columns are codes fitted through the decoder to every vertex (the \
         counterpart of the linear methods' least-squares weights).\n\n",
    );
    let chosen = chosen_on_validation(cfg, results);
    if cfg.select_on_validation {
        md.push_str(
            "**Selection** (`sweep.select = \"validation\"`): per dataset, the cell of lowest *validation* Erms \
             (frames held out of the training split, `data.validation`) is marked **chosen**; the test columns \
             were not used to choose and are reported for it unchanged.\n\n",
        );
        let p = out.join("selection.csv");
        let mut csv = String::from("dataset,method,K,validation_erms,test_erms\n");
        for r in chosen.iter().flatten().map(|&i| &results[i]) {
            let _ = writeln!(csv, "{},{},{},{},{}", r.dataset, r.method, r.k, opt(r.validation_erms), r.test_erms);
        }
        write_atomic(&p, csv.as_bytes())?;
        files.push(p);
    } else {
        let _ = std::fs::remove_file(out.join("selection.csv"));
    }
    if !failed.is_empty() {
        let _ =
            writeln!(md, "**{} cell(s) failed** (marked in the tables; errors in `failed_cells.csv`).\n", failed.len());
    }
    for (di, d) in cfg.datasets.iter().enumerate() {
        let rows: Vec<&CellResult> = results.iter().filter(|r| r.dataset == d.name).collect();
        let chosen_row = chosen[di].map(|i| &results[i]);
        let _ = writeln!(
            md,
            "## {}\n\n`{}`, train `{}`, test `{}`{}\n",
            d.name,
            d.data.path,
            d.data.train,
            d.data.test.as_ref().map(|t| t.to_string()).unwrap_or_default(),
            if d.ordered { ", ordered sequence" } else { ", unordered shapes" }
        );
        md.push_str(
            "| method | representation | K | train Erms | validation Erms | test Erms | test Erms, network only | test Erms, one pass | test Erms, fitted codes | alignment | STED s | STED t | STED s, fitted | STED t, fitted | in-support share | support size | regions | seconds |\n\
             |---|---|---:|---:|---:|---:|---:|---:|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|\n",
        );
        for r in &rows {
            let _ = writeln!(
                md,
                "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |",
                if chosen_row.is_some_and(|c| std::ptr::eq(c, *r)) {
                    format!("**{}** (chosen on validation)", r.method)
                } else {
                    r.method.clone()
                },
                r.representation,
                r.k,
                f(r.train_erms, 3),
                fo(r.validation_erms, 3),
                f(r.test_erms, 3),
                fo(r.test_erms_network, 3),
                fo(r.test_erms_one_pass, 3),
                fo(r.test_erms_fitted, 3),
                r.alignment,
                f(r.sted_spatial, 4),
                fo(r.sted_temporal, 4),
                fo(r.sted_spatial_fitted, 4),
                fo(r.sted_temporal_fitted, 4),
                fo(r.in_support_share, 3),
                fo(r.support_size, 0),
                fo(r.support_regions, 1),
                f(r.seconds, 1)
            );
        }
        for r in failed.iter().filter(|r| r.dataset == d.name) {
            let _ = writeln!(
                md,
                "| {} | — | {} | **failed** | {} | | | | | | | | | | | | | |",
                r.method,
                r.k,
                r.error.replace('|', "\\|").replace('\n', " ")
            );
        }
        md.push('\n');
        let methods: Vec<&str> = cfg.methods.iter().map(|m| m.label.as_str()).collect();
        let series_of = |y: &dyn Fn(&CellResult) -> Option<f64>| -> Vec<Series> {
            methods
                .iter()
                .filter_map(|m| {
                    let points: Vec<(f64, f64)> =
                        rows.iter().filter(|r| r.method == *m).filter_map(|r| y(r).map(|v| (r.k as f64, v))).collect();
                    (!points.is_empty()).then(|| Series { label: m.to_string(), points })
                })
                .collect()
        };
        let erms_png = format!("erms_{}.png", d.name);
        line_plot(
            &out.join(&erms_png),
            &format!("{}: test Erms vs K", d.name),
            "components K",
            "test Erms",
            &series_of(&|r| Some(r.test_erms)),
        )?;
        let sted_png = format!("sted_{}.png", d.name);
        line_plot(
            &out.join(&sted_png),
            &format!("{}: STED (spatial) vs K", d.name),
            "components K",
            "STED spatial",
            &series_of(&|r| Some(r.sted_spatial)),
        )?;
        let _ = writeln!(md, "![test Erms vs K]({erms_png})\n\n![STED vs K]({sted_png})\n");
        if d.ordered {
            let png = format!("sted_temporal_{}.png", d.name);
            line_plot(
                &out.join(&png),
                &format!("{}: STED (temporal) vs K", d.name),
                "components K",
                "STED temporal",
                &series_of(&|r| r.sted_temporal),
            )?;
            let _ = writeln!(md, "![temporal STED vs K]({png})\n");
            files.push(out.join(png));
        }
        files.push(out.join(erms_png));
        files.push(out.join(sted_png));

        if rows.iter().any(|r| r.recovery.is_some()) {
            recovery_section(&mut md, &mut files, out, d, &rows)?;
        }

        let cps: Vec<&ControlPointRow> = cp.iter().filter(|r| r.dataset == d.name).collect();
        if !cps.is_empty() {
            let mut counts: Vec<usize> = cps.iter().map(|r| r.erms.n).collect();
            counts.sort_unstable();
            counts.dedup();
            let mut labels: Vec<(String, usize)> = Vec::new();
            for r in &cps {
                if !labels.iter().any(|(m, _)| *m == r.method) {
                    labels.push((r.method.clone(), r.k));
                }
            }
            let _ = writeln!(
                md,
                "### {}: reconstruction from n control points\n\nTest Erms (no alignment), mean over farthest-point \
                 trials (random start vertex); trials per method: {}.\n",
                d.name,
                labels
                    .iter()
                    .map(|(m, _)| format!("{m} {}", cps.iter().find(|r| r.method == *m).map_or(0, |r| r.erms.trials)))
                    .collect::<Vec<_>>()
                    .join(", ")
            );
            md.push_str("| method | K |");
            for n in &counts {
                let _ = write!(md, " n = {n} |");
            }
            md.push_str("\n|---|---:|");
            md.push_str(&"---:|".repeat(counts.len()));
            md.push('\n');
            for (m, k) in &labels {
                let _ = write!(md, "| {m} | {k} |");
                for n in &counts {
                    let v = cps.iter().find(|r| r.method == *m && r.erms.n == *n).map(|r| r.erms.erms_mean);
                    let _ = write!(md, " {} |", fo(v, 3));
                }
                md.push('\n');
            }
            let series: Vec<Series> = labels
                .iter()
                .map(|(m, k)| Series {
                    label: format!("{m} (K = {k})"),
                    points: cps
                        .iter()
                        .filter(|r| r.method == *m)
                        .map(|r| (r.erms.n as f64, r.erms.erms_mean))
                        .collect(),
                })
                .collect();
            let png = format!("control_points_{}.png", d.name);
            line_plot(
                &out.join(&png),
                &format!("{}: Erms vs number of control points", d.name),
                "control points n",
                "test Erms",
                &series,
            )?;
            let _ = writeln!(md, "\n![Erms vs control points]({png})\n");
            files.push(out.join(png));
        }
    }
    let p = out.join("report.md");
    write_atomic(&p, md.as_bytes())?;
    files.push(p);
    Ok(files)
}
