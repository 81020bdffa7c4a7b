//! The elevator bank: cars moving between floors, their doors, hall and car calls, the light
//! curtain and the traffic of other passengers. Pure state, stepped by the simulator with the
//! robot's whereabouts; deterministic for a seed and a sequence of steps and calls.
//!
//! A car's doors go closed → opening (`door_s`) → open (`dwell_s`) → closing (`door_s`) →
//! closed. A car moves (1/`travel_s` floors a second) only with its doors closed, toward its
//! nearest requested floor, and opens on arrival. A closing door reopens, and an open one
//! stays open, while the robot's centre is within [`CURTAIN`] of the doorway (on that floor
//! or inside that car): nobody is crushed. An idle car with closed doors and without the robot
//! goes, after an exponentially distributed time (mean `traffic_s`), to a random other floor
//! and opens there: cars come and go on the robot's floor too.

use crate::building::Elevator;
use crate::sim::{RADIUS, Rng};
use crate::world::{P, Segment, point_segment};

/// How near the doorway the robot's centre holds the doors open (m).
pub const CURTAIN: f64 = RADIUS + 0.15;

/// A car's doors.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Doors {
    /// Shut: the car may move.
    Closed,
    /// Opening.
    Opening,
    /// Open, closing when `left` seconds are up.
    Open {
        /// Dwell left (s).
        left: f64,
    },
    /// Closing.
    Closing,
}

/// One car.
#[derive(Debug, Clone, PartialEq)]
pub struct Car {
    /// Position in floors (2.0: at floor 2); whole at a floor.
    pos: f64,
    /// Requested floors (bit f).
    requests: u16,
    doors: Doors,
    /// How far the doors are open (0 closed, 1 open).
    open: f64,
    /// Seconds before another passenger sends this idle car elsewhere (`None`: not idle, or
    /// not yet drawn).
    idle_left: Option<f64>,
}

impl Car {
    /// Position in floors.
    pub fn position(&self) -> f64 {
        self.pos
    }

    /// The floor the car is at (`None` while it is between floors).
    pub fn floor(&self) -> Option<i32> {
        let f = self.pos.round();
        ((self.pos - f).abs() < 1e-9).then_some(f as i32)
    }

    /// The floor it is at or nearest to (what its indicator shows).
    pub fn nearest_floor(&self) -> i32 {
        self.pos.round() as i32
    }

    /// Its doors.
    pub fn doors(&self) -> Doors {
        self.doors
    }

    /// How far its doors are open (0 closed, 1 open).
    pub fn open_fraction(&self) -> f64 {
        self.open
    }

    /// Whether floor `f` is requested.
    pub fn requested(&self, f: i32) -> bool {
        (0..16).contains(&f) && self.requests & (1 << f) != 0
    }

    /// The requested floor nearest to `pos` (the lower one of two as near).
    fn nearest_request(pos: f64, requests: u16) -> Option<i32> {
        (0..16).filter(|f| requests & (1 << f) != 0).min_by(|a, b| {
            (f64::from(*a) - pos)
                .abs()
                .total_cmp(&(f64::from(*b) - pos).abs())
        })
    }
}

/// Where the robot is, as the cars see it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rider {
    /// Its centre (m).
    pub at: P,
    /// The floor it is on (`None` while it rides a moving car).
    pub floor: Option<i32>,
    /// The car it is inside.
    pub inside: Option<usize>,
}

/// The cars.
#[derive(Debug, Clone)]
pub struct Bank {
    cars: Vec<Car>,
    /// Each car's doorway, for the light curtain.
    doorways: Vec<Segment>,
    floors: i32,
    travel_s: f64,
    door_s: f64,
    dwell_s: f64,
    traffic_s: f64,
    /// Random source of the starting floors, tie breaks and traffic.
    rng: Rng,
    /// Out of service (fault injection): a car whose doors are closed stays where it is, its
    /// requests kept for when it is back.
    pub out_of_service: bool,
}

impl Bank {
    /// Cars as `spec` describes them serving `floors` floors, each at a random floor with its
    /// doors closed.
    pub fn new(spec: &Elevator, floors: usize, mut rng: Rng) -> Bank {
        // At most MAX_FLOORS (10) floors: the request bits fit a u16.
        let floors = floors.clamp(1, 16) as i32;
        let cars = spec
            .cars
            .iter()
            .map(|_| Car {
                pos: ((rng.uniform() * f64::from(floors)) as i32)
                    .min(floors - 1)
                    .into(),
                requests: 0,
                doors: Doors::Closed,
                open: 0.0,
                idle_left: None,
            })
            .collect();
        Bank {
            cars,
            doorways: spec.cars.iter().map(|c| c.door).collect(),
            floors,
            travel_s: spec.travel_s,
            door_s: spec.door_s,
            dwell_s: spec.dwell_s,
            traffic_s: spec.traffic_s,
            rng,
            out_of_service: false,
        }
    }

    /// The cars, in order (car k + 1 is `cars()[k]`).
    pub fn cars(&self) -> &[Car] {
        &self.cars
    }

    /// Advances `dt` seconds with the robot at `rider`.
    pub fn step(&mut self, dt: f64, rider: Rider) {
        for k in 0..self.cars.len() {
            let curtain = self.curtain(k, rider);
            let (door_s, dwell_s) = (self.door_s, self.dwell_s);
            let car = &mut self.cars[k];
            match car.doors {
                Doors::Opening => {
                    car.open = (car.open + dt / door_s).min(1.0);
                    if car.open >= 1.0 {
                        car.doors = Doors::Open { left: dwell_s };
                    }
                }
                Doors::Open { left } => {
                    let left = (left - dt).max(0.0);
                    car.doors = if left > 0.0 || curtain {
                        Doors::Open { left }
                    } else {
                        Doors::Closing
                    };
                }
                Doors::Closing if curtain => car.doors = Doors::Opening,
                Doors::Closing => {
                    car.open = (car.open - dt / door_s).max(0.0);
                    if car.open <= 0.0 {
                        car.doors = Doors::Closed;
                    }
                }
                Doors::Closed if self.out_of_service => {}
                Doors::Closed => self.drive(k, dt, rider),
            }
        }
    }

    /// Whether the robot stands in car `k`'s doorway on the floor the car is at.
    fn curtain(&self, k: usize, rider: Rider) -> bool {
        let car = &self.cars[k];
        let here = rider.inside == Some(k) || (rider.floor.is_some() && rider.floor == car.floor());
        here && point_segment(rider.at, &self.doorways[k]).0 <= CURTAIN
    }

    /// A car with closed doors: toward its nearest request, or idle.
    fn drive(&mut self, k: usize, dt: f64, rider: Rider) {
        let Bank {
            cars,
            rng,
            floors,
            travel_s,
            traffic_s,
            ..
        } = self;
        let car = &mut cars[k];
        match Car::nearest_request(car.pos, car.requests) {
            Some(f) => {
                car.idle_left = None;
                let d = f64::from(f) - car.pos;
                let step = dt / *travel_s;
                if d.abs() <= step {
                    car.pos = f64::from(f);
                    car.requests &= !(1 << f);
                    car.doors = Doors::Opening;
                    tracing::debug!(car = k + 1, floor = f, "car arrives");
                } else {
                    car.pos += step * d.signum();
                }
            }
            // Nobody else calls a car the robot is in (nor one with nowhere else to go).
            None if rider.inside == Some(k) || *floors < 2 => car.idle_left = None,
            None => {
                let left = car
                    .idle_left
                    .unwrap_or_else(|| -*traffic_s * (1.0 - rng.uniform()).ln())
                    - dt;
                if left > 0.0 {
                    car.idle_left = Some(left);
                    return;
                }
                car.idle_left = None;
                let here = car.nearest_floor();
                let mut to = ((rng.uniform() * f64::from(*floors - 1)) as i32).min(*floors - 2);
                if to >= here {
                    to += 1;
                }
                car.requests |= 1 << to;
                tracing::debug!(car = k + 1, from = here, to, "traffic");
            }
        }
    }

    /// The hall call button pressed on `floor`: a car there with its doors not closed holds
    /// them open; else the car that can come soonest (ties drawn at random) is sent. Returns
    /// the car (0-based).
    pub fn hall_call(&mut self, floor: i32) -> usize {
        let here = (0..self.cars.len())
            .find(|&k| self.cars[k].floor() == Some(floor) && self.cars[k].doors != Doors::Closed);
        if let Some(k) = here {
            self.reopen(k);
            return k;
        }
        if let Some(k) = (0..self.cars.len()).find(|&k| self.cars[k].requested(floor)) {
            return k;
        }
        let etas: Vec<f64> = self.cars.iter().map(|c| self.eta(c, floor)).collect();
        let best = etas.iter().copied().fold(f64::INFINITY, f64::min);
        let ties: Vec<usize> = (0..etas.len())
            .filter(|&k| etas[k] <= best + 1e-6)
            .collect();
        let k = if ties.len() > 1 {
            ties[((self.rng.uniform() * ties.len() as f64) as usize).min(ties.len() - 1)]
        } else {
            ties.first().copied().unwrap_or(0)
        };
        self.request(k, floor);
        tracing::debug!(floor, car = k + 1, eta_s = best, "hall call");
        k
    }

    /// Car `k`'s panel button for `floor` pressed: the floor is requested, or, the car being
    /// there, its doors open again.
    pub fn car_call(&mut self, k: usize, floor: i32) {
        if k >= self.cars.len() || !(0..self.floors).contains(&floor) {
            return;
        }
        if self.cars[k].floor() == Some(floor) {
            self.reopen(k);
        } else {
            self.request(k, floor);
        }
    }

    /// Puts car `k` at `floor` with its doors closed and no requests (the robot resumed in
    /// it).
    pub fn park(&mut self, k: usize, floor: i32) {
        if let Some(car) = self.cars.get_mut(k) {
            car.pos = f64::from(floor.clamp(0, self.floors - 1));
            car.requests = 0;
            car.doors = Doors::Closed;
            car.open = 0.0;
            car.idle_left = None;
        }
    }

    fn request(&mut self, k: usize, floor: i32) {
        if let Some(car) = self.cars.get_mut(k)
            && (0..self.floors).contains(&floor)
        {
            car.requests |= 1 << floor;
            car.idle_left = None;
        }
    }

    fn reopen(&mut self, k: usize) {
        let dwell = self.dwell_s;
        let car = &mut self.cars[k];
        car.doors = match car.doors {
            Doors::Open { .. } => Doors::Open { left: dwell },
            Doors::Closed if car.floor().is_none() => Doors::Closed,
            _ => Doors::Opening,
        };
    }

    /// Seconds until `car` would open at `floor`, serving its requests nearest first.
    fn eta(&self, car: &Car, floor: i32) -> f64 {
        let mut t = match car.doors {
            Doors::Closed => 0.0,
            Doors::Opening => (1.0 - car.open) * self.door_s + self.dwell_s + self.door_s,
            Doors::Open { left } => left + self.door_s,
            Doors::Closing => car.open * self.door_s,
        };
        let mut pos = car.pos;
        let mut requests = car.requests | (1 << floor);
        while let Some(f) = Car::nearest_request(pos, requests) {
            t += (f64::from(f) - pos).abs() * self.travel_s;
            if f == floor {
                break;
            }
            t += 2.0 * self.door_s + self.dwell_s;
            pos = f64::from(f);
            requests &= !(1 << f);
        }
        t
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::building::Shaft;
    use crate::world::Rect;

    fn spec(traffic_s: f64) -> Elevator {
        let shaft = |x: f64| Shaft {
            door: Segment {
                from: [x - 0.55, 0.0],
                to: [x + 0.55, 0.0],
            },
            cabin: Rect {
                min: [x - 0.85, 0.0],
                max: [x + 0.85, 1.7],
            },
        };
        Elevator {
            travel_s: 2.5,
            door_s: 1.5,
            dwell_s: 8.0,
            traffic_s,
            call: [0.0, -0.05],
            cars: vec![shaft(-2.7), shaft(-0.9), shaft(0.9), shaft(2.7)],
        }
    }

    const AWAY: Rider = Rider {
        at: [0.0, -5.0],
        floor: Some(0),
        inside: None,
    };

    fn run(bank: &mut Bank, seconds: f64, rider: Rider) {
        for _ in 0..(seconds * 100.0).round() as usize {
            bank.step(0.01, rider);
        }
    }

    #[test]
    fn a_hall_call_brings_a_car_that_opens_and_closes_again() {
        let mut bank = Bank::new(&spec(1e9), 5, Rng::new(3));
        let k = bank.hall_call(2);
        run(&mut bank, 4.0 * 2.5 + 0.5, AWAY);
        let car = &bank.cars()[k];
        assert_eq!(car.floor(), Some(2));
        assert_ne!(car.doors(), Doors::Closed);
        run(&mut bank, 1.5 + 8.0 + 1.6, AWAY);
        assert_eq!(bank.cars()[k].doors(), Doors::Closed);
        assert_eq!(
            bank.cars()[k].floor(),
            Some(2),
            "no request, no traffic: it stays"
        );
    }

    #[test]
    fn out_of_service_a_closed_car_stays_and_its_call_is_served_once_back() {
        // Traffic every 2 s on average: in service, cars move.
        let mut bank = Bank::new(&spec(2.0), 5, Rng::new(3));
        run(&mut bank, 1.0, AWAY);
        bank.out_of_service = true;
        let k = bank.hall_call(4);
        let before: Vec<f64> = bank.cars().iter().map(Car::position).collect();
        run(&mut bank, 60.0, AWAY);
        let after: Vec<f64> = bank.cars().iter().map(Car::position).collect();
        assert_eq!(before, after, "no car moves while out of service");
        assert!(bank.cars().iter().all(|c| c.doors() == Doors::Closed));
        bank.out_of_service = false;
        run(&mut bank, 4.0 * 2.5 + 1.0, AWAY);
        assert_eq!(
            bank.cars()[k].floor(),
            Some(4),
            "the call kept, served once back"
        );
    }

    #[test]
    fn the_light_curtain_holds_the_doors_while_the_robot_is_in_the_doorway() {
        let mut bank = Bank::new(&spec(1e9), 5, Rng::new(4));
        let k = bank.hall_call(0);
        for _ in 0..2000 {
            bank.step(0.01, AWAY);
            if bank.cars()[k].open_fraction() >= 1.0 {
                break;
            }
        }
        assert_eq!(bank.cars()[k].floor(), Some(0));
        let door = bank.doorways[k];
        let in_door = Rider {
            at: [(door.from[0] + door.to[0]) / 2.0, -0.1],
            floor: Some(0),
            inside: None,
        };
        // Standing there a minute, far past the dwell: the doors never close.
        for _ in 0..6000 {
            bank.step(0.01, in_door);
            assert!(
                bank.cars()[k].open_fraction() > 0.99,
                "{:?}",
                bank.cars()[k]
            );
        }
        // On another floor the same spot holds nothing.
        let elsewhere = Rider {
            floor: Some(3),
            ..in_door
        };
        run(&mut bank, 12.0, elsewhere);
        assert_eq!(bank.cars()[k].doors(), Doors::Closed);
    }

    #[test]
    fn a_closing_door_reopens_for_the_robot() {
        let mut bank = Bank::new(&spec(1e9), 5, Rng::new(5));
        let k = bank.hall_call(1);
        let door = bank.doorways[k];
        for _ in 0..10_000 {
            bank.step(0.01, AWAY);
            if bank.cars()[k].doors() == Doors::Closing && bank.cars()[k].open_fraction() < 0.5 {
                break;
            }
        }
        let rider = Rider {
            at: [(door.from[0] + door.to[0]) / 2.0, -0.4],
            floor: Some(1),
            inside: None,
        };
        bank.step(0.01, rider);
        assert_eq!(bank.cars()[k].doors(), Doors::Opening);
    }

    #[test]
    fn the_car_a_hall_call_sends_depends_on_the_seed() {
        let sent: std::collections::BTreeSet<usize> = (0..40)
            .map(|seed| Bank::new(&spec(60.0), 5, Rng::new(seed)).hall_call(0))
            .collect();
        assert!(sent.len() >= 3, "{sent:?}");
    }

    #[test]
    fn idle_cars_travel_on_their_own() {
        let mut bank = Bank::new(&spec(20.0), 5, Rng::new(6));
        let start: Vec<f64> = bank.cars().iter().map(Car::position).collect();
        let mut moved = [false; 4];
        for _ in 0..30_000 {
            bank.step(0.01, AWAY);
            for (k, c) in bank.cars().iter().enumerate() {
                moved[k] |= c.position() != start[k];
            }
        }
        assert_eq!(moved, [true; 4]);
    }

    #[test]
    fn a_car_call_for_its_own_floor_opens_it() {
        let mut bank = Bank::new(&spec(1e9), 5, Rng::new(7));
        let f = bank.cars()[0].nearest_floor();
        bank.car_call(0, f);
        bank.step(0.01, AWAY);
        assert_eq!(bank.cars()[0].doors(), Doors::Opening);
        assert!(!bank.cars()[0].requested(f));
    }

    #[test]
    fn a_car_with_the_robot_inside_stays_put() {
        let mut bank = Bank::new(&spec(1.0), 5, Rng::new(8));
        let f = bank.cars()[1].position();
        let inside = Rider {
            at: [-0.9, 0.85],
            floor: Some(f as i32),
            inside: Some(1),
        };
        run(&mut bank, 60.0, inside);
        assert_eq!(bank.cars()[1].position(), f);
    }
}
