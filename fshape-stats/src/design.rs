//! The covariates table, the design matrix built from it and contrasts.
//!
//! The table is CSV (or tab-separated) with a header, read by
//! [`fshape_mesh::io::table`]; its first column
//! names the subject, the others are covariates. A column whose values are
//! all numbers is a numeric covariate (entered as it is); a column of
//! names is a factor, entered with treatment coding: its levels sorted,
//! the first the reference, one indicator column per other level, named
//! `column[level]`. The design always has an intercept first.
//!
//! A contrast is written as FSL and PALM users write them: a term's name
//! (`group`, `age`: its columns, a t test for one column, an F test for a
//! factor of more than two levels), a design column's name
//! (`group[patient]`), or weights on the design's columns (`0,1,0`; rows
//! separated by `;` for an F test).

use crate::StatsError;
use crate::linalg;

/// A parsed covariates table.
#[derive(Clone, Debug)]
pub struct Covariates {
    source: String,
    /// The covariates' names (the header without the subject column).
    columns: Vec<String>,
    rows: Vec<Row>,
}

#[derive(Clone, Debug)]
struct Row {
    /// 1-based line in the file.
    line: usize,
    subject: String,
    cells: Vec<String>,
}

/// One term of a design: a numeric covariate or a factor, and the design
/// columns it fills.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Term {
    /// The table column's name (`intercept` for the intercept).
    pub name: String,
    /// The design columns it fills.
    pub columns: std::ops::Range<usize>,
    /// A factor's levels, the reference first (empty for a number).
    pub levels: Vec<String>,
}

/// A design matrix: one row per subject, the intercept first.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Design {
    /// Subjects (rows).
    pub n: usize,
    /// The columns' names.
    pub columns: Vec<String>,
    /// The terms, in order.
    pub terms: Vec<Term>,
    /// n × p, row-major.
    pub x: Vec<f64>,
}

/// A contrast: r rows of weights on the design's columns (r = 1: a t
/// test; r > 1: an F test).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Contrast {
    /// As the user wrote it.
    pub name: String,
    /// r × p, row-major.
    pub weights: Vec<f64>,
    /// Rows.
    pub rank: usize,
}

fn parse_number(cell: &str) -> Option<f64> {
    cell.parse::<f64>().ok()
}

impl Covariates {
    /// Parses the table's text; `source` (its path) names it in errors.
    /// Blank lines and lines starting with `#` are skipped; cells may be
    /// quoted (`"Smith, J"`), and a byte-order mark and CRLF line ends
    /// (what spreadsheets write) are read.
    pub fn parse(text: &str, source: &str) -> Result<Covariates, StatsError> {
        let table = |line: usize, column: Option<&str>, message: String| StatsError::Table {
            table: source.to_string(),
            line,
            column: column.map(str::to_string),
            message,
        };
        // Quoted cells, a byte-order mark, CRLF, tabs: fshape_mesh's table reader.
        let records = fshape_mesh::io::table::parse_table(text.as_bytes()).map_err(|e| {
            let line = match e.at {
                fshape_mesh::io::Location::Line(l) => l,
                fshape_mesh::io::Location::Byte(_) => 0,
            };
            table(line, None, e.kind.to_string())
        })?;
        let mut lines = records.into_iter();
        let Some(fshape_mesh::io::table::Record { line: header_line, fields: names }) = lines.next() else {
            return Err(table(1, None, "empty: expected a header `subject,covariate,…`".into()));
        };
        if names.len() < 2 {
            return Err(table(
                header_line,
                None,
                "the header names no covariate (expected `subject,covariate,…`)".into(),
            ));
        }
        for (k, name) in names.iter().enumerate() {
            if name.is_empty() {
                return Err(table(header_line, None, format!("column {} has no name", k + 1)));
            }
            if names[..k].contains(name) {
                return Err(table(header_line, Some(name), "named twice in the header".into()));
            }
        }
        let mut rows: Vec<Row> = Vec::new();
        for fshape_mesh::io::table::Record { line, fields: cells } in lines {
            if cells.len() != names.len() {
                return Err(table(
                    line,
                    None,
                    format!("{} cells, but the header has {} columns", cells.len(), names.len()),
                ));
            }
            if cells[0].is_empty() {
                return Err(table(line, Some(&names[0]), "no subject named".into()));
            }
            if let Some(other) = rows.iter().find(|r| r.subject == cells[0]) {
                return Err(table(
                    line,
                    Some(&names[0]),
                    format!("subject `{}` already has a row (line {})", cells[0], other.line),
                ));
            }
            rows.push(Row { line, subject: cells[0].clone(), cells: cells[1..].to_vec() });
        }
        if rows.is_empty() {
            return Err(table(header_line, None, "no rows after the header".into()));
        }
        Ok(Covariates { source: source.to_string(), columns: names[1..].to_vec(), rows })
    }

    /// The covariates' names, in the table's order.
    pub fn columns(&self) -> &[String] {
        &self.columns
    }

    /// The design for these subjects, in this order: each subject is given
    /// by the names a row may call it (e.g. its index, its folder, its
    /// file) and must match exactly one row. `columns`: the covariates to
    /// enter (all when `None`). Rows naming no subject are left out and
    /// returned by name.
    pub fn design(
        &self,
        subjects: &[Vec<String>],
        columns: Option<&[String]>,
    ) -> Result<(Design, Vec<String>), StatsError> {
        let table = |line: usize, column: &str, message: String| StatsError::Table {
            table: self.source.clone(),
            line,
            column: Some(column.to_string()),
            message,
        };
        // Each subject's row.
        let mut chosen: Vec<&Row> = Vec::with_capacity(subjects.len());
        for (i, names) in subjects.iter().enumerate() {
            let hits: Vec<&Row> = self.rows.iter().filter(|r| names.contains(&r.subject)).collect();
            match hits.as_slice() {
                [row] => chosen.push(row),
                [] => {
                    return Err(StatsError::MissingSubject {
                        table: self.source.clone(),
                        subject: i,
                        names: names.join(", "),
                    });
                }
                [a, b, ..] => {
                    return Err(table(
                        b.line,
                        "subject",
                        format!(
                            "subject {i} is named both here (`{}`) and on line {} (`{}`)",
                            b.subject, a.line, a.subject
                        ),
                    ));
                }
            }
        }
        // A row is one subject's: a name two subjects share (one's index,
        // another's file stem) must not give both the same row.
        for (i, row) in chosen.iter().enumerate() {
            if let Some(j) = chosen[..i].iter().position(|r| r.line == row.line) {
                return Err(table(
                    row.line,
                    "subject",
                    format!("`{}` names both subject {j} and subject {i}: name them apart", row.subject),
                ));
            }
        }
        let unused: Vec<String> =
            self.rows.iter().filter(|r| !chosen.iter().any(|c| c.line == r.line)).map(|r| r.subject.clone()).collect();
        let wanted: Vec<usize> = match columns {
            None => (0..self.columns.len()).collect(),
            Some(names) => names
                .iter()
                .map(|name| {
                    self.columns.iter().position(|c| c == name).ok_or_else(|| StatsError::Design {
                        message: format!(
                            "`{name}` is not a column of {} (it has: {})",
                            self.source,
                            self.columns.join(", ")
                        ),
                    })
                })
                .collect::<Result<_, _>>()?,
        };
        let n = chosen.len();
        let mut columns: Vec<String> = vec!["intercept".into()];
        let mut terms = vec![Term { name: "intercept".into(), columns: 0..1, levels: Vec::new() }];
        let mut data: Vec<Vec<f64>> = vec![vec![1.0; n]];
        for &c in &wanted {
            let name = &self.columns[c];
            let cells: Vec<(&Row, &str)> = chosen.iter().map(|r| (*r, r.cells[c].as_str())).collect();
            if let Some((row, _)) = cells.iter().find(|(_, v)| v.is_empty()) {
                return Err(table(row.line, name, format!("no value for subject `{}`", row.subject)));
            }
            let numbers: Vec<Option<f64>> = cells.iter().map(|(_, v)| parse_number(v)).collect();
            let start = columns.len();
            if numbers.iter().any(Option::is_some) {
                // A numeric column: every value must be a finite number.
                let example = cells.iter().zip(&numbers).find(|(_, x)| x.is_some()).map(|((r, v), _)| (r.line, *v));
                let mut values = Vec::with_capacity(n);
                for ((row, cell), x) in cells.iter().zip(&numbers) {
                    match x {
                        Some(v) if v.is_finite() => values.push(*v),
                        Some(_) => return Err(table(row.line, name, format!("`{cell}` is not a finite number"))),
                        None => {
                            let (line, v) = example.unwrap_or((row.line, ""));
                            return Err(table(
                                row.line,
                                name,
                                format!(
                                    "`{cell}` is not a number, while line {line} gives `{v}`: a column holds numbers or group names, not both"
                                ),
                            ));
                        }
                    }
                }
                if values.iter().all(|v| *v == values[0]) {
                    return Err(StatsError::Design {
                        message: format!(
                            "{}: column `{name}` is {} for every subject: a constant has no effect to estimate (leave it out)",
                            self.source, values[0]
                        ),
                    });
                }
                columns.push(name.clone());
                data.push(values);
                terms.push(Term { name: name.clone(), columns: start..start + 1, levels: Vec::new() });
            } else {
                let mut levels: Vec<String> = cells.iter().map(|(_, v)| v.to_string()).collect();
                levels.sort();
                levels.dedup();
                if levels.len() < 2 {
                    return Err(StatsError::Design {
                        message: format!(
                            "{}: column `{name}` is `{}` for every subject: a single group has no effect to estimate (leave it out)",
                            self.source, levels[0]
                        ),
                    });
                }
                for level in &levels[1..] {
                    columns.push(format!("{name}[{level}]"));
                    data.push(cells.iter().map(|(_, v)| f64::from(u8::from(v == level))).collect());
                }
                terms.push(Term { name: name.clone(), columns: start..columns.len(), levels });
            }
        }
        let p = columns.len();
        let mut x = vec![0.0; n * p];
        for (j, col) in data.iter().enumerate() {
            for (i, v) in col.iter().enumerate() {
                x[i * p + j] = *v;
            }
        }
        let design = Design { n, columns, terms, x };
        design.check()?;
        Ok((design, unused))
    }
}

impl Design {
    /// A design from its matrix (n × p, row-major) and its columns' names,
    /// one term per column.
    pub fn from_matrix(columns: Vec<String>, x: Vec<f64>) -> Result<Design, StatsError> {
        let p = columns.len();
        if p == 0 || !x.len().is_multiple_of(p) {
            return Err(StatsError::Design { message: format!("{} values do not fill rows of {p} columns", x.len()) });
        }
        if let Some(k) = x.iter().position(|v| !v.is_finite()) {
            return Err(StatsError::Design {
                message: format!("row {}, column `{}`: not a finite number", k / p, columns[k % p]),
            });
        }
        let terms = columns
            .iter()
            .enumerate()
            .map(|(j, c)| Term { name: c.clone(), columns: j..j + 1, levels: Vec::new() })
            .collect();
        let design = Design { n: x.len() / p, columns, terms, x };
        design.check()?;
        Ok(design)
    }

    /// Columns.
    pub fn p(&self) -> usize {
        self.columns.len()
    }

    /// Full column rank and residual degrees of freedom.
    fn check(&self) -> Result<(), StatsError> {
        let p = self.p();
        if self.n <= p {
            return Err(StatsError::Design {
                message: format!(
                    "{} subjects for {p} design columns ({}): a test needs more subjects than columns",
                    self.n,
                    self.columns.join(", ")
                ),
            });
        }
        if let Err(j) = linalg::qr(&self.x, self.n, p) {
            return Err(StatsError::Design {
                message: format!(
                    "column `{}` is a combination of the columns before it ({}): the design is not of full rank",
                    self.columns[j],
                    self.columns[..j].join(", ")
                ),
            });
        }
        Ok(())
    }

    /// The contrast `spec` (see the module's documentation).
    pub fn contrast(&self, spec: &str) -> Result<Contrast, StatsError> {
        let p = self.p();
        let bad = |message: String| StatsError::Contrast { contrast: spec.to_string(), message };
        let spec_t = spec.trim();
        let mut rows: Vec<Vec<f64>> = Vec::new();
        if let Some(term) = self.terms.iter().find(|t| t.name == spec_t) {
            for j in term.columns.clone() {
                let mut w = vec![0.0; p];
                w[j] = 1.0;
                rows.push(w);
            }
        } else if let Some(j) = self.columns.iter().position(|c| c == spec_t) {
            let mut w = vec![0.0; p];
            w[j] = 1.0;
            rows.push(w);
        } else {
            for row in spec_t.split(';') {
                let w: Vec<f64> = row
                    .split(',')
                    .map(|v| {
                        v.trim().parse::<f64>().ok().filter(|x| x.is_finite()).ok_or_else(|| {
                            bad(format!(
                                "`{}` is neither a design column ({}) nor a number",
                                v.trim(),
                                self.columns.join(", ")
                            ))
                        })
                    })
                    .collect::<Result<_, _>>()?;
                if w.len() != p {
                    return Err(bad(format!(
                        "{} weights for {p} design columns ({})",
                        w.len(),
                        self.columns.join(", ")
                    )));
                }
                rows.push(w);
            }
        }
        if rows.iter().any(|w| w[0] != 0.0) {
            return Err(bad(
                "it weighs the intercept, which permutations cannot test (they leave the mean unchanged)".into()
            ));
        }
        let rank = rows.len();
        let weights: Vec<f64> = rows.concat();
        if linalg::qr(&transpose(&weights, rank, p), p, rank).is_err() {
            return Err(bad("its rows are zero or linearly dependent".into()));
        }
        Ok(Contrast { name: spec_t.to_string(), weights, rank })
    }
}

/// The transpose of an r × c row-major matrix.
pub(crate) fn transpose(a: &[f64], r: usize, c: usize) -> Vec<f64> {
    let mut t = vec![0.0; r * c];
    for i in 0..r {
        for j in 0..c {
            t[j * r + i] = a[i * c + j];
        }
    }
    t
}

#[cfg(test)]
mod tests {
    use super::*;

    fn subjects(n: usize) -> Vec<Vec<String>> {
        (0..n).map(|i| vec![i.to_string(), format!("subject_{i:03}")]).collect()
    }

    fn error(text: &str, n: usize) -> String {
        let table = Covariates::parse(text, "cov.csv").and_then(|c| c.design(&subjects(n), None).map(|_| ()));
        table.expect_err("the table should be refused").to_string()
    }

    #[test]
    fn a_factor_is_coded_against_its_first_level_and_numbers_enter_as_they_are() {
        let text = "subject,group,age\n# a comment\nsubject_000,control,30\n1,patient,41.5\n2,control,35\n3,patient,33\nextra,patient,50\n";
        let (d, unused) = Covariates::parse(text, "cov.csv").unwrap().design(&subjects(4), None).unwrap();
        assert_eq!(d.columns, ["intercept", "group[patient]", "age"]);
        assert_eq!(d.x, [1.0, 0.0, 30.0, 1.0, 1.0, 41.5, 1.0, 0.0, 35.0, 1.0, 1.0, 33.0]);
        assert_eq!(unused, ["extra"]);
        assert_eq!(d.terms[1].levels, ["control", "patient"]);
        let c = d.contrast("group").unwrap();
        assert_eq!((c.weights.as_slice(), c.rank), ([0.0, 1.0, 0.0].as_slice(), 1));
        assert_eq!(d.contrast("0,0,-1").unwrap().weights, [0.0, 0.0, -1.0]);
    }

    #[test]
    fn a_spreadsheet_export_with_a_quoted_comma_a_bom_and_crlf_is_read() {
        let text = "\u{feff}subject,clinician,age\r\n0,\"Smith, J\",30\r\n1,\"Doe, A\",41\r\n2,\"Smith, J\",35\r\n\
                    3,\"Doe, A\",38\r\n";
        let table = Covariates::parse(text, "cov.csv").unwrap();
        assert_eq!(table.columns(), ["clinician", "age"]);
        let (d, _) = table.design(&subjects(4), None).unwrap();
        assert!(d.columns.contains(&"clinician[Smith, J]".to_string()), "{:?}", d.columns);
        let e = error("subject,age\n0,30\n1,\"31\n", 2);
        assert!(e.contains("line 3") && e.contains("quotes in pairs"), "{e}");
    }

    #[test]
    fn a_factor_of_three_levels_gives_an_f_contrast() {
        let text = "subject\tsite\n0\ta\n1\tb\n2\tc\n3\ta\n4\tb\n";
        let (d, _) = Covariates::parse(text, "cov.tsv").unwrap().design(&subjects(5), None).unwrap();
        let c = d.contrast("site").unwrap();
        assert_eq!(c.rank, 2);
        assert_eq!(c.weights, [0.0, 1.0, 0.0, 0.0, 0.0, 1.0]);
    }

    #[test]
    fn bad_tables_are_refused_naming_the_line_and_column() {
        let missing = error("subject,age\n0,30\n2,31\n", 3);
        assert!(
            missing.contains("subject 1") && missing.contains("subject_001") && missing.contains("no row"),
            "{missing}"
        );
        let text = error("subject,age\n0,30\n1,thirty\n2,31\n", 3);
        assert!(
            text.contains("line 3") && text.contains("`age`") && text.contains("`thirty` is not a number"),
            "{text}"
        );
        let nan = error("subject,age\n0,30\n1,NaN\n2,31\n", 3);
        assert!(nan.contains("line 3") && nan.contains("not a finite number"), "{nan}");
        let constant = error("subject,age,site\n0,30,a\n1,30,b\n2,30,a\n", 3);
        assert!(constant.contains("column `age`") && constant.contains("constant"), "{constant}");
        let one_group = error("subject,site\n0,a\n1,a\n2,a\n", 3);
        assert!(one_group.contains("column `site`") && one_group.contains("single group"), "{one_group}");
        let empty = error("subject,age\n0,30\n1,\n2,31\n", 3);
        assert!(empty.contains("line 3") && empty.contains("`age`") && empty.contains("no value"), "{empty}");
        let short = error("subject,age\n0,30\n1\n2,31\n", 3);
        assert!(short.contains("line 3") && short.contains("1 cells"), "{short}");
        let twice = error("subject,age\n0,30\n0,31\n", 1);
        assert!(twice.contains("line 3") && twice.contains("already has a row (line 2)"), "{twice}");
        let both = error("subject,age\n0,30\nsubject_000,31\n", 1);
        assert!(both.contains("line 3") && both.contains("named both"), "{both}");
        // Subject 1's index is subject 0's other name.
        let shared = Covariates::parse("subject,age\n1,30\n2,31\n", "cov.csv")
            .unwrap()
            .design(&[vec!["0".into(), "1".into()], vec!["1".into()], vec!["2".into()]], None)
            .unwrap_err()
            .to_string();
        assert!(shared.contains("line 2") && shared.contains("names both subject 0 and subject 1"), "{shared}");
        let dependent = error("subject,a,b\n0,1,2\n1,2,4\n2,3,6\n3,5,10\n", 4);
        assert!(dependent.contains("column `b`") && dependent.contains("combination"), "{dependent}");
        let few = error("subject,a,b\n0,1,2\n1,2,4\n2,3,7\n", 3);
        assert!(few.contains("3 subjects for 3 design columns"), "{few}");
    }

    #[test]
    fn bad_contrasts_are_refused() {
        let (d, _) =
            Covariates::parse("subject,age\n0,1\n1,2\n2,4\n", "c").unwrap().design(&subjects(3), None).unwrap();
        for (spec, says) in [("height", "neither"), ("0,1,0", "3 weights for 2"), ("1,0", "intercept"), ("0,0", "zero")]
        {
            let e = d.contrast(spec).expect_err(spec).to_string();
            assert!(e.contains(says), "{spec}: {e}");
        }
    }
}
