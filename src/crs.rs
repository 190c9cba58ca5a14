//! Coordinate reference systems: what a LAS file's (E)VLRs say, read the way the LAS 1.4
//! specification asks, with the EPSG code and the units named.
//!
//! A file may carry an OGC WKT (record 2112), GeoTIFF keys (34735-34737), or both, in any VLR
//! or EVLR. Which one rules is set by the WKT bit of the header's global encoding: with it the
//! WKT, without it the GeoTIFF keys (a file with only the other is read from that one). The
//! EPSG code of a WKT is its root's `AUTHORITY` (WKT1) or `ID` (WKT2).

use crate::error::{Error, Result};
use serde::{Deserialize, Serialize};

/// The coordinate reference system of a cloud.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Crs {
    /// OGC WKT, if the file carries one and it rules.
    pub wkt: Option<String>,
    /// EPSG code of the CRS (projected, else geographic; of the horizontal part of a compound
    /// CRS), if known.
    pub epsg: Option<u32>,
    /// Unit of x and y (e.g. "metre", "US survey foot", "degree"), if the CRS names it.
    pub horizontal_unit: Option<String>,
    /// Unit of z, if the CRS names it.
    pub vertical_unit: Option<String>,
}

/// The range the EPSG dataset's codes lie in (it reserves 1 to 32767, and its coordinate
/// reference systems start at 1024): a code outside it is a typing slip or another
/// authority's (ESRI's 102100), which a reader would take for an EPSG code that does not exist.
pub(crate) const EPSG_CODES: std::ops::RangeInclusive<u32> = 1024..=32767;

impl Crs {
    /// True if nothing is known of the CRS.
    pub fn is_unknown(&self) -> bool {
        self.wkt.is_none() && self.epsg.is_none()
    }

    /// True if two known CRS are the same one: the same EPSG code where both have one (a file
    /// may add a WKT to the code another file gives alone), else the same WKT.
    pub fn agrees(&self, other: &Crs) -> bool {
        match (self.epsg, other.epsg) {
            (Some(a), Some(b)) => a == b,
            _ => self.wkt == other.wkt && self.epsg == other.epsg,
        }
    }

    /// One-line description for humans, with the units where known.
    ///
    /// ```
    /// use crease::crs::Crs;
    /// let wkt = r#"PROJCS["NAD83 / Ohio North (ftUS)",GEOGCS["NAD83",UNIT["degree",0.0174532925199433]],UNIT["US survey foot",0.304800609601219],AUTHORITY["EPSG","3734"]]"#;
    /// let crs = Crs::from_wkt(wkt);
    /// assert_eq!(crs.epsg, Some(3734));
    /// assert_eq!(crs.summary(), "EPSG:3734 (units: US survey foot)");
    /// ```
    pub fn summary(&self) -> String {
        let name = match (&self.epsg, &self.wkt) {
            (Some(code), _) => format!("EPSG:{code}"),
            // The name is the first quoted string of the WKT.
            (None, Some(wkt)) => format!("WKT \"{}\"", wkt.split('"').nth(1).unwrap_or("WKT")),
            (None, None) => return "unknown".to_string(),
        };
        match self.units() {
            Some(u) => format!("{name} (units: {u})"),
            None => name,
        }
    }

    /// The units as "horizontal" or "horizontal, vertical" (None if the CRS names none).
    pub fn units(&self) -> Option<String> {
        match (&self.horizontal_unit, &self.vertical_unit) {
            (Some(h), Some(v)) if h != v => Some(format!("{h} horizontal, {v} vertical")),
            (Some(h), _) => Some(h.clone()),
            (None, Some(v)) => Some(format!("unknown horizontal, {v} vertical")),
            (None, None) => None,
        }
    }

    /// The CRS a WKT describes (its code and units read from it).
    pub fn from_wkt(wkt: &str) -> Crs {
        let wkt = wkt.trim_end_matches('\0').trim().to_string();
        let root = Node::parse(&wkt);
        let (horizontal_unit, vertical_unit) = root.as_ref().map(units_of).unwrap_or_default();
        Crs { epsg: root.as_ref().and_then(epsg_of), wkt: Some(wkt), horizontal_unit, vertical_unit }
    }

    /// The CRS a free-text CRS field names (E57's `coordinateMetadata`): a WKT naming a code
    /// or units, `EPSG:N`, or an OGC URN `urn:ogc:def:crs:EPSG::N`; None for anything else.
    ///
    /// ```
    /// use crease::crs::Crs;
    /// assert_eq!(Crs::from_metadata("EPSG:25832").unwrap().epsg, Some(25832));
    /// assert_eq!(Crs::from_metadata("urn:ogc:def:crs:EPSG::2056").unwrap().epsg, Some(2056));
    /// assert!(Crs::from_metadata("site grid, mm").is_none());
    /// ```
    pub fn from_metadata(text: &str) -> Option<Crs> {
        let t = text.trim_end_matches('\0').trim();
        let lower = t.to_ascii_lowercase();
        let code = lower.strip_prefix("epsg:").or_else(|| lower.strip_prefix("urn:ogc:def:crs:epsg::")).or_else(|| lower.strip_prefix("urn:ogc:def:crs:epsg:"));
        if let Some(code) = code {
            return code.trim().parse().ok().map(|c| Crs { epsg: Some(c), ..Default::default() });
        }
        Node::parse(t)?;
        Some(Crs::from_wkt(t)).filter(|c| c.epsg.is_some() || c.horizontal_unit.is_some())
    }

    /// The CRS a user names on the command line: `EPSG:N` or a WKT.
    ///
    /// ```
    /// use crease::crs::Crs;
    /// assert_eq!(Crs::parse_user("EPSG:32610").unwrap().epsg, Some(32610));
    /// assert!(Crs::parse_user("UTM 10").is_err());
    /// assert!(Crs::parse_user("EPSG:99999999").is_err());
    /// ```
    pub fn parse_user(s: &str) -> Result<Crs> {
        let s = s.trim();
        if let Some(code) = s.strip_prefix("EPSG:").or_else(|| s.strip_prefix("epsg:")) {
            let epsg = code.parse::<u32>().map_err(|_| Error::Usage(format!("--a-srs: '{code}' is not an EPSG code")))?;
            if !EPSG_CODES.contains(&epsg) {
                return Err(Error::Usage(format!(
                    "--a-srs: EPSG:{epsg} is outside the codes of the EPSG dataset ({} to {}); give another authority's CRS as a WKT",
                    EPSG_CODES.start(),
                    EPSG_CODES.end()
                )));
            }
            return Ok(Crs { epsg: Some(epsg), ..Default::default() });
        }
        match Node::parse(s) {
            Some(_) => Ok(Crs::from_wkt(s)),
            None => Err(Error::Usage(format!("--a-srs: '{s}' is neither EPSG:N nor a WKT"))),
        }
    }

    /// The CRS that a LAS file's records give. `records` are the (user id, record id, data)
    /// of every VLR and EVLR, in file order; `wkt_bit` is bit 4 of the global encoding.
    pub(crate) fn from_las_records<'a>(records: impl IntoIterator<Item = (&'a str, u16, &'a [u8])>, wkt_bit: bool) -> Crs {
        let (mut wkt, mut keys) = (None, None);
        for (user, id, data) in records {
            if user != "LASF_Projection" {
                continue;
            }
            match id {
                2112 if wkt.is_none() => {
                    let text = String::from_utf8_lossy(data).trim_end_matches('\0').trim().to_string();
                    wkt = (!text.is_empty()).then_some(text);
                }
                34735 if keys.is_none() => keys = Some(geo_keys(data)),
                _ => {}
            }
        }
        let from_keys = |keys: Vec<(u16, u16)>| {
            let key = |k: u16| keys.iter().find(|e| e.0 == k).map(|e| e.1).filter(|&v| v != 0 && v != 32767);
            let epsg = key(3072).or_else(|| key(2048)).map(u32::from);
            let horizontal_unit = match key(3072) {
                Some(_) => key(3076).and_then(unit_name),
                None => key(2048).map(|_| "degree".to_string()),
            };
            Crs { wkt: None, epsg, horizontal_unit, vertical_unit: key(4099).and_then(unit_name) }
        };
        // Without the WKT bit the keys rule, unless they name no code (a user-defined CRS,
        // 32767, described in full only by the WKT beside them).
        let keyed = keys.map(from_keys).filter(|k| k.epsg.is_some());
        match (wkt, keyed) {
            (Some(w), _) if wkt_bit => Crs::from_wkt(&w),
            (_, Some(k)) => k,
            (Some(w), None) => Crs::from_wkt(&w),
            (None, None) => Crs::default(),
        }
    }
}

/// GeoTIFF key entries stored in the key directory itself (location 0), as (key, value).
fn geo_keys(data: &[u8]) -> Vec<(u16, u16)> {
    let words: Vec<u16> = data.chunks_exact(2).map(|w| u16::from_le_bytes([w[0], w[1]])).collect();
    let n = words.get(3).copied().unwrap_or(0) as usize;
    words.get(4..).unwrap_or(&[]).chunks_exact(4).take(n).filter(|e| e[1] == 0).map(|e| (e[0], e[3])).collect()
}

/// The name of an EPSG linear unit code as GeoTIFF keys give it.
fn unit_name(code: u16) -> Option<String> {
    Some(
        match code {
            9001 => "metre",
            9002 => "foot",
            9003 => "US survey foot",
            9036 => "kilometre",
            _ => return None,
        }
        .to_string(),
    )
}

/// A WKT node: `KEYWORD[value, ...]`.
#[derive(Debug)]
struct Node {
    keyword: String,
    values: Vec<Value>,
}

#[derive(Debug)]
enum Value {
    Text(String),
    Number(String),
    Node(Node),
}

impl Node {
    /// Parses a WKT (1 or 2); None if it is not one.
    fn parse(s: &str) -> Option<Node> {
        let mut p = Parser { s: s.as_bytes(), at: 0 };
        let n = p.node(0)?;
        p.blank();
        (p.at == p.s.len()).then_some(n)
    }

    fn children(&self) -> impl Iterator<Item = &Node> {
        self.values.iter().filter_map(|v| if let Value::Node(n) = v { Some(n) } else { None })
    }

    fn child(&self, keywords: &[&str]) -> Option<&Node> {
        self.children().find(|c| keywords.iter().any(|k| c.keyword.eq_ignore_ascii_case(k)))
    }

    fn text(&self, k: usize) -> Option<&str> {
        match self.values.get(k)? {
            Value::Text(t) | Value::Number(t) => Some(t),
            Value::Node(_) => None,
        }
    }
}

struct Parser<'a> {
    s: &'a [u8],
    at: usize,
}

impl Parser<'_> {
    fn blank(&mut self) {
        while self.s.get(self.at).is_some_and(|c| c.is_ascii_whitespace()) {
            self.at += 1;
        }
    }

    fn node(&mut self, depth: usize) -> Option<Node> {
        // (A bound on nesting: a hostile WKT must not exhaust the stack.)
        if depth > 64 {
            return None;
        }
        self.blank();
        let start = self.at;
        while self.s.get(self.at).is_some_and(|c| c.is_ascii_alphanumeric() || *c == b'_') {
            self.at += 1;
        }
        let keyword = std::str::from_utf8(&self.s[start..self.at]).ok()?.to_string();
        if keyword.is_empty() {
            return None;
        }
        self.blank();
        let close = match self.s.get(self.at)? {
            b'[' => b']',
            b'(' => b')',
            _ => return None,
        };
        self.at += 1;
        let mut values = vec![];
        loop {
            self.blank();
            match *self.s.get(self.at)? {
                c if c == close && values.is_empty() => {}
                b'"' => {
                    // A quote inside a string is doubled.
                    let mut text = vec![];
                    self.at += 1;
                    loop {
                        match *self.s.get(self.at)? {
                            b'"' if self.s.get(self.at + 1) == Some(&b'"') => {
                                text.push(b'"');
                                self.at += 2;
                            }
                            b'"' => break,
                            c => {
                                text.push(c);
                                self.at += 1;
                            }
                        }
                    }
                    self.at += 1;
                    values.push(Value::Text(String::from_utf8_lossy(&text).into_owned()));
                }
                c if c.is_ascii_digit() || c == b'-' || c == b'+' || c == b'.' => {
                    let start = self.at;
                    while self.s.get(self.at).is_some_and(|c| c.is_ascii_alphanumeric() || b"+-.".contains(c)) {
                        self.at += 1;
                    }
                    values.push(Value::Number(String::from_utf8_lossy(&self.s[start..self.at]).into_owned()));
                }
                c if c.is_ascii_alphabetic() => {
                    // A keyword with brackets is a node; without, an enumeration value (an
                    // axis direction such as `north`, a coordinate system type).
                    let start = self.at;
                    let word = self.s[start..].iter().take_while(|c| c.is_ascii_alphanumeric() || **c == b'_').count();
                    let after = self.s[start + word..].iter().find(|c| !c.is_ascii_whitespace());
                    if matches!(after, Some(b'[') | Some(b'(')) {
                        values.push(Value::Node(self.node(depth + 1)?));
                    } else {
                        self.at += word;
                        values.push(Value::Text(String::from_utf8_lossy(&self.s[start..self.at]).into_owned()));
                    }
                }
                _ => return None,
            }
            self.blank();
            match *self.s.get(self.at)? {
                b',' => self.at += 1,
                c if c == close => {
                    self.at += 1;
                    return Some(Node { keyword, values });
                }
                _ => return None,
            }
        }
    }
}

const COMPOUND: &[&str] = &["COMPD_CS", "COMPOUNDCRS"];
const VERTICAL: &[&str] = &["VERT_CS", "VERTCS", "VERTCRS", "VERTICALCRS"];
const AUTHORITY: &[&str] = &["AUTHORITY", "ID"];

/// The EPSG code of a CRS node: its own, or that of the horizontal part of a compound CRS.
fn epsg_of(n: &Node) -> Option<u32> {
    let own = n.child(AUTHORITY).filter(|a| a.text(0).is_some_and(|t| t.eq_ignore_ascii_case("EPSG"))).and_then(|a| a.text(1)?.trim().parse().ok());
    let compound = COMPOUND.iter().any(|k| n.keyword.eq_ignore_ascii_case(k));
    // (A compound CRS's own code names the pair; the horizontal part's is what GIS tools place
    // the curves by, so it is preferred.)
    if compound
        && let Some(h) =
            n.children().find(|c| !VERTICAL.iter().any(|k| c.keyword.eq_ignore_ascii_case(k)) && !AUTHORITY.iter().any(|k| c.keyword.eq_ignore_ascii_case(k)))
    {
        return epsg_of(h).or(own);
    }
    own
}

/// The unit of a single (not compound) CRS node: its direct UNIT, or the first unit of its
/// coordinate system's axes (WKT2).
fn unit_of(n: &Node) -> Option<String> {
    const UNITS: &[&str] = &["UNIT", "LENGTHUNIT", "ANGLEUNIT"];
    if let Some(u) = n.child(UNITS) {
        return u.text(0).map(str::to_string);
    }
    n.children().filter(|c| c.keyword.eq_ignore_ascii_case("AXIS")).find_map(|a| a.child(UNITS)?.text(0).map(str::to_string))
}

/// (horizontal, vertical) units of a CRS node.
fn units_of(n: &Node) -> (Option<String>, Option<String>) {
    if COMPOUND.iter().any(|k| n.keyword.eq_ignore_ascii_case(k)) {
        let is_vertical = |c: &&Node| VERTICAL.iter().any(|k| c.keyword.eq_ignore_ascii_case(k));
        let horizontal = n.children().find(|c| !is_vertical(c) && !AUTHORITY.iter().any(|k| c.keyword.eq_ignore_ascii_case(k)));
        return (horizontal.and_then(unit_of), n.children().find(is_vertical).and_then(unit_of));
    }
    if VERTICAL.iter().any(|k| n.keyword.eq_ignore_ascii_case(k)) {
        return (None, unit_of(n));
    }
    // (Some writers nest the vertical CRS inside the projected one instead of a compound.)
    let vertical = n.children().find(|c| VERTICAL.iter().any(|k| c.keyword.eq_ignore_ascii_case(k)));
    (unit_of(n), vertical.and_then(unit_of))
}

#[cfg(test)]
mod tests {
    use super::*;

    const FEET: &str = r#"COMPD_CS["NAD83 / Texas North Central (ftUS) + NAVD88 height (ftUS)",PROJCS["NAD83 / Texas North Central (ftUS)",GEOGCS["NAD83",DATUM["North_American_Datum_1983",SPHEROID["GRS 1980",6378137,298.257222101,AUTHORITY["EPSG","7019"]],AUTHORITY["EPSG","6269"]],PRIMEM["Greenwich",0],UNIT["degree",0.0174532925199433],AUTHORITY["EPSG","4269"]],PROJECTION["Lambert_Conformal_Conic_2SP"],UNIT["US survey foot",0.304800609601219,AUTHORITY["EPSG","9003"]],AUTHORITY["EPSG","2276"]],VERT_CS["NAVD88 height (ftUS)",VERT_DATUM["North American Vertical Datum 1988",2005],UNIT["US survey foot",0.304800609601219],AUTHORITY["EPSG","6360"]]]"#;

    #[test]
    fn a_compound_wkt_gives_its_horizontal_code_and_both_units() {
        let c = Crs::from_wkt(FEET);
        assert_eq!(c.epsg, Some(2276));
        assert_eq!((c.horizontal_unit.as_deref(), c.vertical_unit.as_deref()), (Some("US survey foot"), Some("US survey foot")));
    }

    #[test]
    fn a_wkt2_gives_its_id_and_axis_units() {
        let w = r#"PROJCRS["WGS 84 / UTM zone 10N",BASEGEOGCRS["WGS 84",DATUM["World Geodetic System 1984",ELLIPSOID["WGS 84",6378137,298.257223563]]],CONVERSION["UTM zone 10N",METHOD["Transverse Mercator"]],CS[Cartesian,2],AXIS["easting (E)",east,LENGTHUNIT["metre",1]],AXIS["northing (N)",north,LENGTHUNIT["metre",1]],ID["EPSG",32610]]"#;
        let c = Crs::from_wkt(w);
        assert_eq!((c.epsg, c.horizontal_unit.as_deref()), (Some(32610), Some("metre")));
    }

    #[test]
    fn the_wkt_bit_decides_which_record_rules() {
        // GeoTIFF keys: projected CRS 32104 (key 3072), linear unit metre (key 3076 = 9001).
        let keys: Vec<u8> = [1u16, 1, 0, 2, 3072, 0, 1, 32104, 3076, 0, 1, 9001].iter().flat_map(|w| w.to_le_bytes()).collect();
        let records = || [("LASF_Projection", 34735u16, &keys[..]), ("LASF_Projection", 2112, FEET.as_bytes())];
        assert_eq!(Crs::from_las_records(records(), true).epsg, Some(2276));
        let keyed = Crs::from_las_records(records(), false);
        assert_eq!((keyed.epsg, keyed.horizontal_unit.as_deref(), keyed.wkt), (Some(32104), Some("metre"), None));
    }

    #[test]
    fn crs_with_the_same_epsg_agree_with_or_without_a_wkt() {
        let code = Crs { epsg: Some(32104), ..Default::default() };
        let both = Crs { wkt: Some("PROJCS[\"NAD83 / Texas Central\"]".into()), epsg: Some(32104), ..Default::default() };
        let other = Crs { epsg: Some(4326), ..Default::default() };
        let wkt_only = Crs { wkt: Some("PROJCS[\"x\"]".into()), ..Default::default() };
        assert!(code.agrees(&both) && both.agrees(&code));
        assert!(!code.agrees(&other) && !both.agrees(&other));
        assert!(wkt_only.agrees(&wkt_only.clone()) && !wkt_only.agrees(&code));
    }

    #[test]
    fn malformed_wkt_is_not_a_crs_code() {
        for w in ["", "PROJCS[", "PROJCS[\"x\"", "x[[[[", &"A[".repeat(10_000)] {
            assert_eq!(Crs::from_wkt(w).epsg, None);
        }
        assert!(Crs::parse_user("PROJCS[\"x\"").is_err());
    }
}
