//! `fmaps info`: a mesh's validation report.

use super::*;

pub(crate) fn info(path: &Path, json: bool) -> Result<(), Failure> {
    let mesh = load(path)?;
    let mut o = String::new();
    let r = mesh.validate();
    if json {
        let mut v = serde_json::to_value(&r).map_err(runtime)?;
        v["mesh"] = json!(path.display().to_string());
        v["is_manifold"] = json!(r.is_manifold());
        v["is_closed_manifold"] = json!(r.is_closed_manifold());
        v["is_clean"] = json!(r.is_clean());
        return emit(&format!(
            "{}\n",
            serde_json::to_string_pretty(&v).map_err(runtime)?
        ));
    }
    let list = |v: &[usize]| -> String {
        if v.is_empty() {
            "none".into()
        } else {
            let head: Vec<String> = v.iter().take(8).map(|x| x.to_string()).collect();
            format!(
                "{} ({}{})",
                v.len(),
                head.join(", "),
                if v.len() > 8 { ", ..." } else { "" }
            )
        }
    };
    outln!(o, "{}", path.display());
    outln!(
        o,
        "  vertices {}  faces {}  edges {}",
        r.n_vertices,
        r.n_faces,
        r.n_edges
    );
    outln!(
        o,
        "  area {:.6}  bounding box {:?} .. {:?}",
        r.area,
        r.bounding_box[0],
        r.bounding_box[1]
    );
    outln!(
        o,
        "  connected components {}  boundary loops {} ({} edges)",
        r.connected_components,
        r.boundary_loops,
        r.boundary_edges
    );
    outln!(
        o,
        "  Euler characteristic {}  genus {}",
        r.euler_characteristic,
        r.genus
            .map_or("undefined (not a manifold)".into(), |g| g.to_string())
    );
    outln!(o, "  degenerate faces {}", list(&r.degenerate_faces));
    outln!(o, "  duplicate faces {}", list(&r.duplicate_faces));
    outln!(o, "  non-manifold edges {}", r.non_manifold_edges.len());
    outln!(
        o,
        "  non-manifold vertices {}",
        list(&r.non_manifold_vertices)
    );
    outln!(
        o,
        "  unreferenced vertices {}",
        list(&r.unreferenced_vertices)
    );
    outln!(
        o,
        "  inconsistently oriented edges {}",
        r.inconsistently_oriented_edges
    );
    outln!(
        o,
        "  verdict: {}",
        if r.is_clean() {
            "clean manifold mesh"
        } else if r.is_manifold() {
            "manifold, with the defects above"
        } else {
            "NOT a manifold"
        }
    );
    emit(&o)
}
