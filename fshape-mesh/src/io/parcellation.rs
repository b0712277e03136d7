//! Parcellations: a region key per vertex and the table that names the
//! keys, as FreeSurfer's `.annot` files ([`super::freesurfer::parse_annot`]),
//! GIfTI label arrays ([`super::gifti::parcellation`]) and CIFTI-2 label
//! files ([`super::cifti::Cifti::parcellation`]) hold them.
//! fshape takes a parcellation as a mask (the vertices of chosen regions)
//! or carries it, key by key, from one surface to another.

use super::ParseErrorKind;

/// One region of a parcellation's table.
#[derive(Clone, Debug, PartialEq)]
pub struct Region {
    /// The key the vertices of this region carry.
    pub key: i32,
    /// Its name (`precentral`, `???`).
    pub name: String,
    /// Its colour, red, green, blue and alpha in [0, 1].
    pub rgba: [f64; 4],
}

/// A key per vertex and the regions' table.
///
/// For a FreeSurfer `.annot` a key is the row of the colour table (as
/// nibabel's `read_annot` gives it) and −1 marks a vertex without a region;
/// for a GIfTI label array or a CIFTI-2 label file a key is the file's
/// label key (a CIFTI structure's left-out vertices carry its `???` key,
/// or −1).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Parcellation {
    /// The key of each vertex.
    pub keys: Vec<i32>,
    /// The table, in file order.
    pub regions: Vec<Region>,
}

impl Parcellation {
    /// The mask of the vertices in the named regions (1 there, 0
    /// elsewhere). A name that is not in the table is an error listing the
    /// names that are.
    pub fn mask(&self, names: &[&str]) -> Result<Vec<f64>, ParseErrorKind> {
        let mut keys = Vec::with_capacity(names.len());
        for name in names {
            let Some(r) = self.regions.iter().find(|r| r.name == *name) else {
                return Err(ParseErrorKind::UnknownName {
                    what: "region",
                    name: name.to_string(),
                    available: self.regions.iter().map(|r| r.name.clone()).collect(),
                });
            };
            keys.push(r.key);
        }
        Ok(self.keys.iter().map(|k| if keys.contains(k) { 1.0 } else { 0.0 }).collect())
    }

    /// The name of a key, if the table has it.
    pub fn name(&self, key: i32) -> Option<&str> {
        self.regions.iter().find(|r| r.key == key).map(|r| r.name.as_str())
    }
}
