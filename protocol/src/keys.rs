//! The one place that builds and parses Zenoh key expressions (DESIGN §3).
//!
//! Everything lives under `fleet/<site>/…` so one router rule can route a whole site. Builders
//! take validated ids, whose characters can never form a wildcard, separator or verbatim chunk,
//! and fixed literal chunks; the results are therefore always valid, canonical key expressions and
//! the builders are infallible (the tests check every allowed character and every literal).

use zenoh::key_expr::OwnedKeyExpr;

use crate::ids::{MapName, RobotId, SiteId, TaskId, WorkerId};

/// First chunk of every fleet key.
pub const ROOT: &str = "fleet";
const ROBOT: &str = "robot";
const MAP: &str = "map";
const TASK: &str = "task";
const WORKER: &str = "worker";
const CYCLE: &str = "cycle";
const ALIVE: &str = "alive";
const OUTCOME: &str = "outcome";

/// The per-robot topics.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum RobotTopic {
    Scan,
    Odom,
    Camera,
    CmdVel,
    Pose,
    Intention,
    Status,
    /// Liveliness token.
    Alive,
}

impl RobotTopic {
    pub const ALL: [RobotTopic; 8] = [
        RobotTopic::Scan,
        RobotTopic::Odom,
        RobotTopic::Camera,
        RobotTopic::CmdVel,
        RobotTopic::Pose,
        RobotTopic::Intention,
        RobotTopic::Status,
        RobotTopic::Alive,
    ];

    pub fn as_str(self) -> &'static str {
        match self {
            RobotTopic::Scan => "scan",
            RobotTopic::Odom => "odom",
            RobotTopic::Camera => "camera",
            RobotTopic::CmdVel => "cmd_vel",
            RobotTopic::Pose => "pose",
            RobotTopic::Intention => "intention",
            RobotTopic::Status => "status",
            RobotTopic::Alive => "alive",
        }
    }

    pub fn from_chunk(chunk: &str) -> Option<RobotTopic> {
        Self::ALL.into_iter().find(|t| t.as_str() == chunk)
    }
}

impl std::fmt::Display for RobotTopic {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// Joins chunks that are each a validated id, a literal above, `*` or `**`.
fn join(chunks: &[&str]) -> OwnedKeyExpr {
    match OwnedKeyExpr::try_from(chunks.join("/")) {
        Ok(key) => key,
        // Unreachable by construction: ids admit only [A-Za-z0-9_.-] without a leading dot and
        // literals are fixed; `every_id_character_forms_a_valid_key` and the builder tests cover
        // every case. Failing loudly beats publishing on a wrong key.
        Err(e) => unreachable!("fleet key chunks {chunks:?} formed an invalid key expression: {e}"),
    }
}

/// `fleet/<site>/robot/<robot_id>/<topic>`
pub fn robot(site: &SiteId, robot_id: &RobotId, topic: RobotTopic) -> OwnedKeyExpr {
    join(&[
        ROOT,
        site.as_str(),
        ROBOT,
        robot_id.as_str(),
        topic.as_str(),
    ])
}

/// `fleet/<site>/robot/<robot_id>/*`: every topic of one robot.
pub fn robot_any_topic(site: &SiteId, robot_id: &RobotId) -> OwnedKeyExpr {
    join(&[ROOT, site.as_str(), ROBOT, robot_id.as_str(), "*"])
}

/// `fleet/<site>/robot/*/<topic>`: one topic of every robot.
pub fn all_robots(site: &SiteId, topic: RobotTopic) -> OwnedKeyExpr {
    join(&[ROOT, site.as_str(), ROBOT, "*", topic.as_str()])
}

/// `fleet/<site>/robot/*/alive`: the liveliness tokens of every robot.
pub fn alive_all(site: &SiteId) -> OwnedKeyExpr {
    all_robots(site, RobotTopic::Alive)
}

/// `fleet/<site>/map/<name>`: the latest version of a map.
pub fn map_latest(site: &SiteId, name: &MapName) -> OwnedKeyExpr {
    join(&[ROOT, site.as_str(), MAP, name.as_str()])
}

/// `fleet/<site>/map/<name>/<version>`: one version of a map.
pub fn map_version(site: &SiteId, name: &MapName, version: u32) -> OwnedKeyExpr {
    join(&[
        ROOT,
        site.as_str(),
        MAP,
        name.as_str(),
        &version.to_string(),
    ])
}

/// `fleet/<site>/map/**`: what the map store declares its queryable on.
pub fn map_queryable(site: &SiteId) -> OwnedKeyExpr {
    join(&[ROOT, site.as_str(), MAP, "**"])
}

/// `fleet/<site>/task/<task_id>`
pub fn task(site: &SiteId, task_id: &TaskId) -> OwnedKeyExpr {
    join(&[ROOT, site.as_str(), TASK, task_id.as_str()])
}

/// `fleet/<site>/task/*`
pub fn all_tasks(site: &SiteId) -> OwnedKeyExpr {
    join(&[ROOT, site.as_str(), TASK, "*"])
}

/// `fleet/<site>/worker/<worker_id>/alive`: a replanning worker's liveliness token.
pub fn worker_alive(site: &SiteId, worker: &WorkerId) -> OwnedKeyExpr {
    join(&[ROOT, site.as_str(), WORKER, worker.as_str(), ALIVE])
}

/// `fleet/<site>/worker/*/alive`: the liveliness tokens of every worker.
pub fn workers_alive(site: &SiteId) -> OwnedKeyExpr {
    join(&[ROOT, site.as_str(), WORKER, "*", ALIVE])
}

/// `fleet/<site>/cycle/<robot_id>`: a worker's query for what a robot's replanning cycle is
/// to do (the service's task book answers).
pub fn cycle(site: &SiteId, robot_id: &RobotId) -> OwnedKeyExpr {
    join(&[ROOT, site.as_str(), CYCLE, robot_id.as_str()])
}

/// `fleet/<site>/cycle/*`: what the service declares its cycle queryable on.
pub fn cycle_queryable(site: &SiteId) -> OwnedKeyExpr {
    join(&[ROOT, site.as_str(), CYCLE, "*"])
}

/// `fleet/<site>/cycle/<robot_id>/outcome`: how a worker's cycle for a robot ended.
pub fn cycle_outcome(site: &SiteId, robot_id: &RobotId) -> OwnedKeyExpr {
    join(&[ROOT, site.as_str(), CYCLE, robot_id.as_str(), OUTCOME])
}

/// `fleet/<site>/cycle/*/outcome`: every robot's cycle outcomes.
pub fn all_cycle_outcomes(site: &SiteId) -> OwnedKeyExpr {
    join(&[ROOT, site.as_str(), CYCLE, "*", OUTCOME])
}

/// `fleet/<site>/**`: everything of a site (router rules, recording, debugging).
pub fn site_all(site: &SiteId) -> OwnedKeyExpr {
    join(&[ROOT, site.as_str(), "**"])
}

/// Splits `fleet/<site>/<section>/<rest…>` into the site and the remaining chunks.
fn split_site<'a>(key: &'a str, section: &str) -> Option<(SiteId, Vec<&'a str>)> {
    let mut chunks = key.split('/');
    if chunks.next()? != ROOT {
        return None;
    }
    let site = SiteId::new(chunks.next()?).ok()?;
    if chunks.next()? != section {
        return None;
    }
    Some((site, chunks.collect()))
}

/// Parses `fleet/<site>/robot/<robot_id>/<topic>`.
pub fn parse_robot_key(key: &str) -> Option<(SiteId, RobotId, RobotTopic)> {
    let (site, rest) = split_site(key, ROBOT)?;
    match rest.as_slice() {
        [robot_id, topic] => Some((
            site,
            RobotId::new(*robot_id).ok()?,
            RobotTopic::from_chunk(topic)?,
        )),
        _ => None,
    }
}

/// Parses `fleet/<site>/map/<name>` (version None) or `fleet/<site>/map/<name>/<version>`.
pub fn parse_map_key(key: &str) -> Option<(SiteId, MapName, Option<u32>)> {
    let (site, rest) = split_site(key, MAP)?;
    match rest.as_slice() {
        [name] => Some((site, MapName::new(*name).ok()?, None)),
        [name, version] => Some((
            site,
            MapName::new(*name).ok()?,
            Some(parse_version(version)?),
        )),
        _ => None,
    }
}

/// Parses `fleet/<site>/task/<task_id>`.
pub fn parse_task_key(key: &str) -> Option<(SiteId, TaskId)> {
    let (site, rest) = split_site(key, TASK)?;
    match rest.as_slice() {
        [task_id] => Some((site, TaskId::new(*task_id).ok()?)),
        _ => None,
    }
}

/// Parses `fleet/<site>/worker/<worker_id>/alive`.
pub fn parse_worker_alive_key(key: &str) -> Option<(SiteId, WorkerId)> {
    let (site, rest) = split_site(key, WORKER)?;
    match rest.as_slice() {
        [worker_id, alive] if *alive == ALIVE => Some((site, WorkerId::new(*worker_id).ok()?)),
        _ => None,
    }
}

/// Parses `fleet/<site>/cycle/<robot_id>` (`false`) or `fleet/<site>/cycle/<robot_id>/outcome`
/// (`true`).
pub fn parse_cycle_key(key: &str) -> Option<(SiteId, RobotId, bool)> {
    let (site, rest) = split_site(key, CYCLE)?;
    match rest.as_slice() {
        [robot_id] => Some((site, RobotId::new(*robot_id).ok()?, false)),
        [robot_id, outcome] if *outcome == OUTCOME => {
            Some((site, RobotId::new(*robot_id).ok()?, true))
        }
        _ => None,
    }
}

/// Only canonical decimal (no sign, no leading zeros), so that parse and build round-trip.
fn parse_version(chunk: &str) -> Option<u32> {
    let canonical = chunk.bytes().all(|b| b.is_ascii_digit())
        && !chunk.is_empty()
        && (chunk == "0" || !chunk.starts_with('0'));
    if canonical {
        chunk.parse().ok()
    } else {
        None
    }
}

#[cfg(test)]
mod tests {
    use zenoh::key_expr::keyexpr;

    use super::*;

    fn site() -> SiteId {
        SiteId::new("hq").unwrap()
    }

    #[test]
    fn worker_and_cycle_keys_round_trip_and_stay_apart() {
        let w = WorkerId::new("w-1").unwrap();
        let r = RobotId::new("robot_1").unwrap();
        let alive = worker_alive(&site(), &w);
        assert_eq!(alive.as_str(), "fleet/hq/worker/w-1/alive");
        assert!(workers_alive(&site()).intersects(&alive));
        assert_eq!(parse_worker_alive_key(&alive), Some((site(), w)));
        let query = cycle(&site(), &r);
        let outcome = cycle_outcome(&site(), &r);
        assert_eq!(query.as_str(), "fleet/hq/cycle/robot_1");
        assert_eq!(outcome.as_str(), "fleet/hq/cycle/robot_1/outcome");
        assert_eq!(parse_cycle_key(&query), Some((site(), r.clone(), false)));
        assert_eq!(parse_cycle_key(&outcome), Some((site(), r, true)));
        // The queryable never sees outcomes, the outcome subscriber never sees queries.
        assert!(cycle_queryable(&site()).intersects(&query));
        assert!(!cycle_queryable(&site()).intersects(&outcome));
        assert!(all_cycle_outcomes(&site()).intersects(&outcome));
        assert!(!all_cycle_outcomes(&site()).intersects(&query));
        assert_eq!(parse_cycle_key("fleet/hq/cycle/robot_1/other"), None);
        assert_eq!(parse_worker_alive_key("fleet/hq/worker/w-1/other"), None);
    }

    #[test]
    fn builds_the_documented_keys() {
        let r = RobotId::new("robot_1").unwrap();
        let m = MapName::new("floor-2").unwrap();
        let t = TaskId::new("t.42").unwrap();
        assert_eq!(
            robot(&site(), &r, RobotTopic::CmdVel).as_str(),
            "fleet/hq/robot/robot_1/cmd_vel"
        );
        assert_eq!(
            robot_any_topic(&site(), &r).as_str(),
            "fleet/hq/robot/robot_1/*"
        );
        assert_eq!(
            all_robots(&site(), RobotTopic::Pose).as_str(),
            "fleet/hq/robot/*/pose"
        );
        assert_eq!(alive_all(&site()).as_str(), "fleet/hq/robot/*/alive");
        assert_eq!(map_latest(&site(), &m).as_str(), "fleet/hq/map/floor-2");
        assert_eq!(
            map_version(&site(), &m, 7).as_str(),
            "fleet/hq/map/floor-2/7"
        );
        assert_eq!(map_queryable(&site()).as_str(), "fleet/hq/map/**");
        assert_eq!(task(&site(), &t).as_str(), "fleet/hq/task/t.42");
        assert_eq!(all_tasks(&site()).as_str(), "fleet/hq/task/*");
        assert_eq!(site_all(&site()).as_str(), "fleet/hq/**");
    }

    #[test]
    fn wildcards_match_what_they_should() {
        let r = RobotId::new("r1").unwrap();
        let m = MapName::new("office").unwrap();
        for topic in RobotTopic::ALL {
            let k = robot(&site(), &r, topic);
            assert!(all_robots(&site(), topic).intersects(&k));
            assert!(robot_any_topic(&site(), &r).intersects(&k));
            assert!(site_all(&site()).intersects(&k));
            assert!(!map_queryable(&site()).intersects(&k));
        }
        assert!(map_queryable(&site()).intersects(&map_latest(&site(), &m)));
        assert!(map_queryable(&site()).intersects(&map_version(&site(), &m, 3)));
        let other = SiteId::new("lab").unwrap();
        assert!(!all_robots(&other, RobotTopic::Pose).intersects(&robot(
            &site(),
            &r,
            RobotTopic::Pose
        )));
    }

    #[test]
    fn every_id_character_forms_a_valid_key() {
        let allowed: String = ('A'..='Z')
            .chain('a'..='z')
            .chain('0'..='9')
            .chain(['_', '.', '-'])
            .collect();
        let mut samples = vec![allowed[..64].to_string(), allowed[64..].to_string()];
        for c in allowed.chars() {
            samples.push(c.to_string());
            samples.push(format!("a{c}{c}"));
            samples.push(format!("x{c}"));
        }
        samples.push("a..b".into());
        samples.push("-".into());
        samples.push("z".repeat(64));
        for s in samples {
            let Ok(id) = RobotId::new(s.clone()) else {
                continue;
            };
            assert!(keyexpr::new(id.as_str()).is_ok(), "{s}");
            let site = SiteId::new(s.clone()).unwrap();
            let name = MapName::new(s.chars().take(MapName::MAX_LEN).collect::<String>()).unwrap();
            let task_id = TaskId::new(s.clone()).unwrap();
            for topic in RobotTopic::ALL {
                let k = robot(&site, &id, topic);
                assert_eq!(k.as_str(), format!("{ROOT}/{s}/{ROBOT}/{s}/{topic}"));
                assert_eq!(parse_robot_key(&k), Some((site.clone(), id.clone(), topic)));
            }
            assert_eq!(
                parse_map_key(&map_version(&site, &name, u32::MAX)),
                Some((site.clone(), name.clone(), Some(u32::MAX)))
            );
            assert_eq!(
                parse_task_key(&task(&site, &task_id)),
                Some((site.clone(), task_id.clone()))
            );
            let _ = (
                map_queryable(&site),
                all_tasks(&site),
                alive_all(&site),
                site_all(&site),
            );
        }
    }

    #[test]
    fn parse_round_trips() {
        let r = RobotId::new("r-2.b").unwrap();
        for topic in RobotTopic::ALL {
            assert_eq!(
                parse_robot_key(&robot(&site(), &r, topic)),
                Some((site(), r.clone(), topic))
            );
        }
        let m = MapName::new("office").unwrap();
        assert_eq!(
            parse_map_key(&map_latest(&site(), &m)),
            Some((site(), m.clone(), None))
        );
        assert_eq!(
            parse_map_key(&map_version(&site(), &m, 0)),
            Some((site(), m.clone(), Some(0)))
        );
        let t = TaskId::new("task_9").unwrap();
        assert_eq!(parse_task_key(&task(&site(), &t)), Some((site(), t)));
    }

    #[test]
    fn parse_rejects_foreign_keys() {
        for k in [
            "",
            "fleet",
            "other/hq/robot/r1/pose",
            "fleet/hq/robot/r1",
            "fleet/hq/robot/r1/pose/extra",
            "fleet/hq/robot/r1/unknown",
            "fleet/hq/robot/*/pose",
            "fleet/hq/map/r1/pose",
            "fleet/hq/task/t1",
        ] {
            assert_eq!(parse_robot_key(k), None, "{k}");
        }
        for k in [
            "fleet/hq/map",
            "fleet/hq/map/office/01",
            "fleet/hq/map/office/+1",
            "fleet/hq/map/office/4294967296",
            "fleet/hq/map/office/1/x",
            "fleet/hq/map/**",
            "fleet/hq/task/office",
        ] {
            assert_eq!(parse_map_key(k), None, "{k}");
        }
        for k in [
            "fleet/hq/task",
            "fleet/hq/task/a/b",
            "fleet/hq/task/*",
            "fleet/hq/map/t1",
        ] {
            assert_eq!(parse_task_key(k), None, "{k}");
        }
    }
}
